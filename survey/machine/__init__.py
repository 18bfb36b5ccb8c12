"""The machine under the model: how survey compiles (numba's decorators, its disk cache kept
in step with the kernel sources, the vector width LLVM is told to use) and the arithmetic
that gives the same bits on every x86-64 machine (elementary functions, matrix
algorithms). Imports nothing of the package; every compiled layer stands on it."""
