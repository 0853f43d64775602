"""How every kernel is compiled."""

import numba

# nogil: tiles run on threads side by side with Embree. No fast math: the kernels test for NaN rays on purpose,
# and a painting's recursion amplifies any reordering of float operations
# cache=True: compiled once per machine. numba's cache does not notice a change to a kernel that another kernel
# calls from another module (``iterate.paint_iteration`` calls them all): after editing one, remove
# ``rcp_server/**/__pycache__/*.nb[ci]`` (a fresh clone has none)
jit = numba.njit(nogil=True, cache=True, error_model="numpy")
