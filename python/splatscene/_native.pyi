"""Type stubs of the native module ``splatscene._native`` (the Rust library through PyO3).
The package ``splatscene`` wraps it; its classes are what users hold."""

import os
from typing import Any, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

__all__ = ["Mesh", "Scene", "SplatsceneError", "Volume", "encode_png", "error", "load_volume", "order"]

_PathLike = Union[str, os.PathLike]
_Vec3 = Sequence[float]

class SplatsceneError(Exception):
    """What the library refused: a file it cannot read, a scene that does not load."""

@final
class Volume:
    @staticmethod
    def from_array(
        array: np.ndarray,
        spacing: Optional[_Vec3] = ...,
        origin: Optional[_Vec3] = ...,
        direction: Optional[Any] = ...,
        axes: str = ...,
    ) -> Volume: ...
    @property
    def array(self) -> np.ndarray: ...
    @property
    def dims(self) -> Tuple[int, int, int]: ...
    @property
    def spacing(self) -> Tuple[float, float, float]: ...
    @property
    def origin(self) -> Tuple[float, float, float]: ...
    @property
    def direction(self) -> npt.NDArray[np.float64]: ...
    @property
    def affine(self) -> npt.NDArray[np.float64]: ...
    @property
    def frame(self) -> int: ...
    @property
    def format(self) -> Optional[str]: ...
    @property
    def scalar_type(self) -> Optional[str]: ...
    @property
    def path(self) -> Optional[str]: ...
    def info(self) -> dict: ...

def load_volume(
    path: _PathLike,
    *,
    series: Optional[Union[str, int]] = ...,
    skip_unreadable: bool = ...,
    frame: Optional[int] = ...,
    nifti_transform: Optional[str] = ...,
    coordinate_frame: Optional[str] = ...,
    dims: Optional[Sequence[int]] = ...,
    scalar: Optional[str] = ...,
    header_bytes: Optional[int] = ...,
    spacing: Optional[_Vec3] = ...,
    origin: Optional[_Vec3] = ...,
    orientation: Optional[str] = ...,
) -> Volume: ...

@final
class Mesh:
    @staticmethod
    def from_file(
        path: _PathLike,
        *,
        units: Optional[str] = ...,
        frame: Optional[str] = ...,
        name: Optional[str] = ...,
        color: Optional[Sequence[float]] = ...,
        opacity: Optional[float] = ...,
        translate: Optional[_Vec3] = ...,
        rotate_degrees: Optional[_Vec3] = ...,
        scale: Optional[_Vec3] = ...,
        matrix: Optional[Any] = ...,
    ) -> Mesh: ...
    @staticmethod
    def from_arrays(
        vertices: Any,
        faces: Any,
        *,
        name: Optional[str] = ...,
        color: Optional[Sequence[float]] = ...,
        opacity: Optional[float] = ...,
        translate: Optional[_Vec3] = ...,
        rotate_degrees: Optional[_Vec3] = ...,
        scale: Optional[_Vec3] = ...,
        matrix: Optional[Any] = ...,
    ) -> Mesh: ...
    def placed(
        self,
        *,
        translate: Optional[_Vec3] = ...,
        rotate_degrees: Optional[_Vec3] = ...,
        scale: Optional[_Vec3] = ...,
        matrix: Optional[Any] = ...,
    ) -> Mesh: ...
    @property
    def name(self) -> Optional[str]: ...
    @property
    def vertices(self) -> npt.NDArray[np.float32]: ...
    @property
    def faces(self) -> npt.NDArray[np.uint32]: ...

@final
class Scene:
    def __new__(
        cls,
        volumes: Optional[Sequence[Union[Volume, _PathLike]]] = ...,
        meshes: Optional[Sequence[Union[Mesh, _PathLike]]] = ...,
        *,
        transfer: Optional[str] = ...,
        window: Optional[Tuple[float, float]] = ...,
        shift: Optional[float] = ...,
        crop_box: Optional[Tuple[_Vec3, _Vec3]] = ...,
        clip_meshes: Optional[bool] = ...,
        background: Optional[_Vec3] = ...,
        transparent: bool = ...,
        size: Optional[Tuple[int, int]] = ...,
        ordering: Optional[str] = ...,
        view: str = ...,
    ) -> Scene: ...
    @staticmethod
    def from_file(path: _PathLike) -> Scene: ...
    def render(
        self,
        size: Optional[Tuple[int, int]] = ...,
        *,
        view: Optional[str] = ...,
        eye: Optional[_Vec3] = ...,
        target: Optional[_Vec3] = ...,
        orbit: Optional[Tuple[float, float]] = ...,
        fov: Optional[float] = ...,
        orthographic: Optional[float] = ...,
        ordering: Optional[str] = ...,
        annotate: Optional[Union[bool, str]] = ...,
        caption: Optional[str] = ...,
        depth: bool = ...,
        depth_mode: Optional[str] = ...,
        surface_opacity: float = ...,
        lod: Union[bool, str, None] = ...,
        transparent: bool = ...,
    ) -> Union[npt.NDArray[np.uint8], Tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32]]]: ...
    def pick(
        self,
        pixel: Tuple[int, int],
        size: Optional[Tuple[int, int]] = ...,
        *,
        view: Optional[str] = ...,
        eye: Optional[_Vec3] = ...,
        target: Optional[_Vec3] = ...,
        orbit: Optional[Tuple[float, float]] = ...,
        fov: Optional[float] = ...,
        orthographic: Optional[float] = ...,
        opacity: float = ...,
        meshes_only: bool = ...,
    ) -> dict: ...
    def contact(self, mesh: Optional[str] = ..., *, classes: Optional[Sequence[float]] = ...) -> dict: ...
    @property
    def size(self) -> Optional[Tuple[int, int]]: ...
    @property
    def volumes(self) -> list: ...
    @property
    def meshes(self) -> list: ...
    @property
    def camera(self) -> dict: ...
    @property
    def report(self) -> Optional[dict]: ...

def order(
    dims: Sequence[int],
    eye: _Vec3,
    ordering: str = ...,
    *,
    spacing: Optional[_Vec3] = ...,
    target: Optional[_Vec3] = ...,
    cull_behind_eye: bool = ...,
    bucket_width: Optional[float] = ...,
) -> npt.NDArray[np.uint32]: ...
def error(
    volume: Volume,
    eye: _Vec3,
    *,
    target: Optional[_Vec3] = ...,
    orderings: Optional[Sequence[str]] = ...,
    size: Optional[Tuple[int, int]] = ...,
    transfer: Optional[str] = ...,
    window: Optional[Tuple[float, float]] = ...,
) -> list: ...
def encode_png(image: npt.NDArray[np.uint8]) -> bytes: ...
