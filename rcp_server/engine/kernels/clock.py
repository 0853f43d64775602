"""The processor's cycle counter, read from compiled code: how a fused kernel splits its time into stages
(``stopwatch.STAGES``) without returning to Python between them. Cycles, not seconds: the caller shares
the seconds it measured around the kernel in proportion (``Stopwatch.share``)."""

from __future__ import annotations

from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic


@intrinsic
def cycles(typingctx):
    """The cycle counter (``llvm.readcyclecounter``: the time-stamp counter on x86), int64."""

    def codegen(context, builder, signature, args):
        counter = builder.module.declare_intrinsic("llvm.readcyclecounter", fnty=ir.FunctionType(ir.IntType(64), []))
        return builder.call(counter, [])

    return types.int64(), codegen
