"""Print the OpenBLAS kernel each loaded OpenBLAS library runs (its `get_corename`), so that a
run under OPENBLAS_CORETYPE shows the variable took effect. Exit 1 if no OpenBLAS is loaded."""

import ctypes
import sys

import numpy  # noqa: F401 - loads numpy's OpenBLAS
import scipy.linalg  # noqa: F401 - and scipy's

names = []
with open("/proc/self/maps") as fh:
    for line in fh:
        path = line.split()[-1]
        if "openblas" in path and ".so" in path and path not in names:
            names.append(path)
found = 0
for path in names:
    lib = ctypes.CDLL(path)
    for symbol in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename"):
        fn = getattr(lib, symbol, None)
        if fn is not None:
            fn.restype = ctypes.c_char_p
            print(f"{path.rsplit('/', 1)[-1]}: {fn().decode()}")
            found += 1
            break
sys.exit(0 if found else 1)
