"""Compare two dump_fused.py outputs: largest difference, bit-identical or not."""
import sys

import numpy as np

a, b = np.load(sys.argv[1]), np.load(sys.argv[2])
worst, exact = 0.0, True
for k in a.files:
    if a[k].shape != b[k].shape:
        print('shape', k, a[k].shape, b[k].shape)
        exact = False
        continue
    d = np.nanmax(np.abs(a[k].astype(float) - b[k].astype(float))) if a[k].size else 0.0
    worst = max(worst, d)
    exact &= a[k].tobytes() == b[k].tobytes()
print('max abs diff', worst, 'bit-identical', exact)
