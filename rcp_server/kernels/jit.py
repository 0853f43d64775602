"""How every kernel is compiled."""

import numba

# nogil: tiles run on threads side by side with Embree. Fast math without the no-NaN/no-inf assumptions:
# the kernels test for NaN rays on purpose
jit = numba.njit(nogil=True, cache=True, error_model="numpy")
