# Type stubs of the package dvm (examples/python/src/dvm/__init__.py) for editors and type
# checkers; the docstrings are in __init__.py.
import os
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

_Value = Union[bool, int, float, str, Sequence[Any], Mapping[str, Any], np.ndarray]
# None, True (a bar on stderr) or a function progress(step, steps)
_Progress = Union[None, bool, Callable[[int, int], Any]]

class InputError(ValueError):
    message: str
    key: Optional[str]
    source: Optional[str]
    line: Optional[int]
    column: Optional[int]
    def __init__(self, message: str) -> None: ...

class Result:
    report: Dict[str, Any]
    columns: List[str]
    data: npt.NDArray[np.float64]
    t: npt.NDArray[np.float64]
    q: npt.NDArray[np.float64]
    p: npt.NDArray[np.float64]
    energy: npt.NDArray[np.float64]
    # the fields of `dvm run --json`, among them:
    status: str
    system: str
    steps: int
    step: float
    t_final: float
    q_final: List[float]
    p_final: List[float]
    energy_initial: float
    energy_final: float
    max_abs_energy_error: float
    wall_seconds: float
    def __getattr__(self, name: str) -> Any: ...
    def __getitem__(self, name: str) -> npt.NDArray[np.float64]: ...

class StepFailure(RuntimeError):
    message: str
    result: Union[Result, "Convergence"]
    step: Optional[int]
    time: Optional[float]
    residual: Optional[float]
    def __init__(self, message: str, result: Result) -> None: ...

class Scene:
    overrides: List[str]
    path: str
    system: str
    dim: int
    step: float
    steps: int
    every: int
    monitor_every: int
    boundary_value: bool
    method: str
    csv: str
    npy: str

class System:
    keys: Dict[str, Any]
    def __init__(self, builtin: Optional[str] = ..., **keys: _Value) -> None: ...

class Method:
    keys: Dict[str, Any]
    written_map: Optional[Mapping[str, Any]]
    def __init__(self, galerkin: Optional[int] = ..., written_map: Optional[Mapping[str, Any]] = ...,
                 **keys: _Value) -> None: ...

def load_scene(source: Union[str, os.PathLike], **overrides: _Value) -> Scene: ...
def run(scene: Scene, progress: _Progress = ...) -> Result: ...
def integrate(system: System, method: Optional[Method] = ..., *, q0: Optional[_Value] = ...,
              p0: Optional[_Value] = ..., v0: Optional[_Value] = ..., h: Optional[float] = ...,
              steps: Optional[int] = ..., t_end: Optional[float] = ..., every: int = ...,
              monitor_every: Optional[int] = ..., initial: Optional[Mapping[str, _Value]] = ...,
              problem: Optional[Mapping[str, _Value]] = ..., progress: _Progress = ...) -> Result: ...
class Convergence:
    report: Dict[str, Any]
    steps: npt.NDArray[np.int64]
    h: npt.NDArray[np.float64]
    error: npt.NDArray[np.float64]
    order: npt.NDArray[np.float64]
    runs: List[Dict[str, Any]]
    fitted_order: Optional[float]
    reference: str
    reference_accuracy: float
    def __getattr__(self, name: str) -> Any: ...

def converge(scene: Scene, steps: Optional[Sequence[int]] = ..., t_end: Optional[float] = ...,
             max_steps: Optional[int] = ...) -> Convergence: ...
class MapCheck:
    report: Dict[str, Any]
    map: str
    space: str
    theta: Optional[float]
    dim: int
    claims_symmetric: bool
    residuals: Dict[str, Optional[float]]
    tolerance: float
    passed: bool
    def __getattr__(self, name: str) -> Any: ...
    def __bool__(self) -> bool: ...

def check_map(map: Union[str, Scene], theta: Optional[float] = ..., dim: Optional[int] = ...,
              tolerance: float = ...) -> MapCheck: ...
def systems() -> List[Dict[str, Any]]: ...
def maps() -> List[Dict[str, Any]]: ...
def methods() -> List[Dict[str, Any]]: ...
