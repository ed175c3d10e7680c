"""diag_ii.py with and without the fusion's unswap (step 3 of the issue 31 follow-up):
diag_unswap.py SEED CLASSES LAYOUT"""
import runpy
import sys
from pathlib import Path

from pose_reconstruction import fusion as F

orig = F.unswap_permutation
args = sys.argv[1:4]
for on in (False, True):
    F.unswap_permutation = orig if on else (lambda swapped: None)
    print('unswap' if on else 'no unswap', flush=True)
    sys.argv = ['diag_ii.py'] + args
    runpy.run_path(str(Path(__file__).with_name('diag_ii.py')))
