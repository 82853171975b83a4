"""Type stubs of the native module ``splatscene._native`` (the Rust library through PyO3).
The package ``splatscene`` wraps it; its classes are what users hold."""

import os
from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

PathLike = Union[str, os.PathLike]
Vec3 = Sequence[float]

class SplatsceneError(Exception):
    """What the library refused: a file it cannot read, a scene that does not load."""

class Volume:
    @staticmethod
    def from_array(
        array: np.ndarray,
        spacing: Optional[Vec3] = ...,
        origin: Optional[Vec3] = ...,
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
    path: PathLike,
    *,
    series: Optional[Union[str, int]] = ...,
    skip_unreadable: bool = ...,
    frame: Optional[int] = ...,
    nifti_transform: Optional[str] = ...,
    coordinate_frame: Optional[str] = ...,
    dims: Optional[Tuple[int, int, int]] = ...,
    scalar: Optional[str] = ...,
    header_bytes: Optional[int] = ...,
    spacing: Optional[Vec3] = ...,
    origin: Optional[Vec3] = ...,
    orientation: Optional[str] = ...,
) -> Volume: ...

class Mesh:
    @staticmethod
    def from_file(
        path: PathLike,
        *,
        units: Optional[str] = ...,
        frame: Optional[str] = ...,
        name: Optional[str] = ...,
        color: Optional[Sequence[float]] = ...,
        opacity: Optional[float] = ...,
        translate: Optional[Vec3] = ...,
        rotate_degrees: Optional[Vec3] = ...,
        scale: Optional[Vec3] = ...,
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
        translate: Optional[Vec3] = ...,
        rotate_degrees: Optional[Vec3] = ...,
        scale: Optional[Vec3] = ...,
        matrix: Optional[Any] = ...,
    ) -> Mesh: ...
    def placed(
        self,
        *,
        translate: Optional[Vec3] = ...,
        rotate_degrees: Optional[Vec3] = ...,
        scale: Optional[Vec3] = ...,
        matrix: Optional[Any] = ...,
    ) -> Mesh: ...
    @property
    def name(self) -> Optional[str]: ...
    @property
    def vertices(self) -> npt.NDArray[np.float32]: ...
    @property
    def faces(self) -> npt.NDArray[np.uint32]: ...

class Scene:
    def __init__(
        self,
        volumes: Optional[Sequence[Union[Volume, PathLike]]] = ...,
        meshes: Optional[Sequence[Union[Mesh, PathLike]]] = ...,
        *,
        transfer: Optional[str] = ...,
        window: Optional[Tuple[float, float]] = ...,
        shift: Optional[float] = ...,
        crop_box: Optional[Tuple[Vec3, Vec3]] = ...,
        clip_meshes: Optional[bool] = ...,
        background: Optional[Vec3] = ...,
        transparent: bool = ...,
        size: Optional[Tuple[int, int]] = ...,
        ordering: Optional[str] = ...,
        view: str = ...,
    ) -> None: ...
    @staticmethod
    def from_file(path: PathLike) -> Scene: ...
    def render(
        self,
        size: Optional[Tuple[int, int]] = ...,
        *,
        view: Optional[str] = ...,
        eye: Optional[Vec3] = ...,
        target: Optional[Vec3] = ...,
        orbit: Optional[Tuple[float, float]] = ...,
        fov: Optional[float] = ...,
        orthographic: Optional[float] = ...,
        ordering: Optional[str] = ...,
        annotate: Optional[Union[bool, str]] = ...,
        caption: Optional[str] = ...,
        depth: bool = ...,
        depth_mode: Optional[str] = ...,
        surface_opacity: float = ...,
        lod: bool = ...,
        transparent: bool = ...,
    ) -> Union[npt.NDArray[np.uint8], Tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32]]]: ...
    def pick(
        self,
        pixel: Tuple[int, int],
        size: Optional[Tuple[int, int]] = ...,
        *,
        view: Optional[str] = ...,
        eye: Optional[Vec3] = ...,
        target: Optional[Vec3] = ...,
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
    dims: Tuple[int, int, int],
    eye: Vec3,
    ordering: str = ...,
    *,
    spacing: Optional[Vec3] = ...,
    target: Optional[Vec3] = ...,
    cull_behind_eye: bool = ...,
    bucket_width: Optional[float] = ...,
) -> npt.NDArray[np.uint32]: ...
def error(
    volume: Volume,
    eye: Vec3,
    *,
    target: Optional[Vec3] = ...,
    orderings: Optional[Sequence[str]] = ...,
    size: Optional[Tuple[int, int]] = ...,
    transfer: Optional[str] = ...,
    window: Optional[Tuple[float, float]] = ...,
) -> list: ...
def encode_png(image: npt.NDArray[np.uint8]) -> bytes: ...
