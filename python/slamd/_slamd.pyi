"""Type stubs of the extension module (see the docstrings for the contract)."""

from os import PathLike
from typing import Literal, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

Kind = Literal["odometry", "loop_closure", "trusted_loop_closure", "other"]
PoseLike = Union[Sequence[float], npt.NDArray[np.float64]]
InformationLike = Union[Sequence[float], Sequence[Sequence[float]], npt.NDArray[np.float64]]

class SlamdError(ValueError): ...

class Graph:
    @property
    def dimension(self) -> int: ...
    @property
    def ids(self) -> npt.NDArray[np.uint64]: ...
    @property
    def guess(self) -> npt.NDArray[np.float64]: ...
    @property
    def edges(self) -> npt.NDArray[np.uint64]: ...
    @property
    def measurements(self) -> npt.NDArray[np.float64]: ...
    @property
    def information(self) -> npt.NDArray[np.float64]: ...
    @property
    def kinds(self) -> list[Kind]: ...
    def __len__(self) -> int: ...

class Solution:
    chi2: float
    poses: npt.NDArray[np.float64]
    ids: npt.NDArray[np.uint64]
    switches: Optional[npt.NDArray[np.float64]]
    seconds: float

class Snapshot:
    version: int
    chi2: float
    resolves: int
    keyframes: int
    edges: int
    pending: int
    settling: bool
    ids: npt.NDArray[np.uint64]
    poses: npt.NDArray[np.float64]
    timestamps: npt.NDArray[np.uint64]
    covariance_keyframe: Optional[int]
    covariance: Optional[npt.NDArray[np.float64]]
    def __len__(self) -> int: ...

def read(path: Union[str, PathLike[str]], skip_invalid: bool = False) -> Graph: ...
def solve(
    graph: Graph,
    polish: bool = True,
    robust: bool = False,
    formulation: Literal["two-stage", "virtual-frame", "virtual-frame-pivot", "odometry"] = "two-stage",
) -> Solution: ...

class Engine:
    def __init__(self, dimension: int = 2, *, background: bool = True, outlier_filter: bool = True) -> None: ...
    @property
    def dimension(self) -> int: ...
    def add_keyframe(self, id: int, guess: Optional[PoseLike] = None, timestamp_ns: int = 0) -> int: ...
    def add_edge(
        self,
        from_id: int,
        to_id: int,
        measurement: PoseLike,
        information: InformationLike,
        kind: Optional[Kind] = None,
    ) -> int: ...
    def add_gps(
        self,
        keyframe: int,
        lat: float,
        lon: float,
        height: float = 0.0,
        covariance: Sequence[float] = (1.0, 0.0, 0.0, 1.0),
        height_variance: Optional[float] = None,
    ) -> None: ...
    def update(self) -> int: ...
    def resolve_now(self) -> None: ...
    def snapshot(self) -> Snapshot: ...
    def switches(self) -> npt.NDArray[np.float64]: ...
    def set_edge_weight(self, edge: int, weight: float) -> None: ...
    def marginal(self, id: int) -> npt.NDArray[np.float64]: ...
    def joint_marginal(self, a: int, b: int) -> npt.NDArray[np.float64]: ...

class Frontend:
    def __init__(self, namespace: str = "slamd", dimension: int = 2) -> None: ...
    @property
    def id(self) -> int: ...
    @property
    def last_sequence(self) -> int: ...
    def add_keyframe(self, id: int, guess: Optional[PoseLike] = None, timestamp_ns: int = 0) -> int: ...
    def add_edge(
        self,
        from_id: int,
        to_id: int,
        measurement: PoseLike,
        information: InformationLike,
        kind: Optional[Kind] = None,
    ) -> int: ...
    def add_gps(
        self,
        keyframe: int,
        lat: float,
        lon: float,
        height: float = 0.0,
        covariance: Sequence[float] = (1.0, 0.0, 0.0, 1.0),
        height_variance: Optional[float] = None,
    ) -> int: ...
    def flush(self) -> None: ...
    def wait_acknowledged(self, sequence: Optional[int] = None, timeout: float = 10.0) -> bool: ...

class Switches:
    version: int
    edges: npt.NDArray[np.uint64]
    weights: npt.NDArray[np.float64]
    states: list[Literal["kept", "off", "pending"]]

class Snapshots:
    def __init__(self, namespace: str = "slamd") -> None: ...
    def switches(self) -> Optional[Switches]: ...
    def latest(self) -> Optional[Snapshot]: ...
    def wait(self, timeout: float = 5.0) -> Optional[Snapshot]: ...
