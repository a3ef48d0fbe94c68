"""slamd: an online pose-graph SLAM backend, from Python.

- ``read(path)`` reads a g2o, TORO, HOG-Man or iSAM file (2-D or 3-D);
  ``solve(graph, polish=True, robust=False, formulation="two-stage")``
  solves it at once.
- ``Engine(dimension=2)`` is the incremental engine in this process:
  keyframes, edges and GPS fixes in; snapshots, switches and marginal
  covariances out.
- ``Frontend(namespace)`` and ``Snapshots(namespace)`` talk to a running
  ``slamd run`` daemon over shared memory.

Poses are rows ``(x, y, theta)`` in 2-D and ``(x, y, z, qx, qy, qz, qw)``
in 3-D; information matrices are their upper triangle in g2o order (6 or
21 numbers) or the square matrix. Every error is a ``SlamdError`` (a
``ValueError``) carrying slamd's own message.
"""

from ._slamd import (
    Engine,
    Frontend,
    Graph,
    SlamdError,
    Snapshot,
    Snapshots,
    Solution,
    Switches,
    read,
    solve,
)

__all__ = [
    "Engine",
    "Frontend",
    "Graph",
    "SlamdError",
    "Snapshot",
    "Snapshots",
    "Solution",
    "Switches",
    "read",
    "solve",
]
