"""What the bench scripts share: where the datasets and the slamd binary
are, running slamd for its JSON, and the information matrices of g2o's
files.

Scripts run as `python3 benches/NAME.py`, so this directory is on their
path and `from common import ...` finds this module.
"""
import json
import os
import subprocess

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("SLAMD_DATASETS") or os.path.normpath(os.path.join(HERE, "..", "..", "shared", "datasets"))
BIN = os.environ.get("SLAMD_BIN") or os.path.normpath(os.path.join(HERE, "..", "target", "release", "slamd"))


def slamd(*args, binary=BIN, **run):
    """Runs `slamd ARGS` (`binary`, else SLAMD_BIN, else the release build)
    and returns the JSON object it printed last; a failure raises
    CalledProcessError. `run` goes to subprocess.run (env, timeout)."""
    out = subprocess.run([binary, *args], check=True, capture_output=True, text=True, **run).stdout
    return json.loads(out.strip().splitlines()[-1])


def upper(values, n):
    """The symmetric n×n matrix of its upper triangle, row by row (g2o's order)."""
    m, k = np.zeros((n, n)), 0
    for r in range(n):
        for c in range(r, n):
            m[r, c] = m[c, r] = values[k]
            k += 1
    return m


def positive_definite(m):
    """Whether Cholesky takes `m` (what slamd asks of an information matrix)."""
    try:
        np.linalg.cholesky(m)
        return True
    except np.linalg.LinAlgError:
        return False
