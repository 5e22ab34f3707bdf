"""gaussim's compiled kernels, in modules that import numpy and numba alone (not Pinocchio, coal or
ProxQP): the build compiles them into numba's cache (:mod:`gaussim.kernels.prebuild`), so that the first
run after an install does not. The stages call them through their own modules."""
