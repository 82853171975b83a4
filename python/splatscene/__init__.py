"""splatscene for Python: shoulder-prosthesis planning scenes.

A CT volume drawn as one splat per significant voxel, back to front in the IP-PBTF visibility
order (Botha & Post 2005), with implant and bone meshes depth-tested against it; the library
behind the ``splatscene`` command line, with volumes and meshes as numpy arrays and pictures
back as numpy arrays.

    import SimpleITK as sitk
    import splatscene

    ct = splatscene.Volume.from_sitk(sitk.ReadImage("ct.nii.gz"))
    stem = splatscene.Mesh.from_file("stem.stl", translate=(26.7, 163.4, 16.7))
    scene = splatscene.Scene(volumes=[ct], meshes=[stem], transfer="ct-bone")
    picture = scene.render(size=(640, 480), view="anterior", annotate=True)

Positions are millimetres in the patient's RAS frame, as the command line and scene files
take them: +x toward the patient's right, +y anterior, +z superior (NIfTI's convention; DICOM
and SimpleITK's LPS differ by the signs of x and y, which ``Volume.from_sitk`` turns).
"""

from __future__ import annotations

import os
import sys
from typing import Any, Iterable, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import SplatsceneError

__all__ = [
    "Image",
    "Mesh",
    "Scene",
    "SplatsceneError",
    "Volume",
    "error",
    "load_volume",
    "order",
]

PathLike = Union[str, os.PathLike]


class Image(np.ndarray):
    """A rendered picture: a ``(height, width, 4)`` uint8 RGBA numpy array that notebooks show
    (``_repr_png_``) and that ``save`` writes as a PNG file."""

    def __new__(cls, array: np.ndarray) -> "Image":
        return np.asarray(array).view(cls)

    def __array_wrap__(self, array: np.ndarray, context: Any = None, return_scalar: bool = False) -> Any:
        # What numpy computes from a picture (a difference, a mean) is a plain array or number.
        out = np.asarray(array)
        return out[()] if return_scalar else out

    def _repr_png_(self) -> bytes:
        return self.png()

    def png(self) -> bytes:
        """The picture as the bytes of a PNG file."""
        return _native.encode_png(np.ascontiguousarray(np.asarray(self, dtype=np.uint8)))

    def save(self, path: PathLike) -> None:
        """Writes the picture to ``path`` as a PNG file."""
        with open(path, "wb") as f:
            f.write(self.png())


class Volume:
    """A CT or MR volume: values on a regular grid placed in RAS millimetres.

    ``array`` holds the values shaped ``(z, y, x)``, as SimpleITK's ``GetArrayFromImage``
    gives them; ``spacing`` and ``origin`` are given along and at (x, y, z), and the columns
    of ``direction`` are the x, y and z index axes, all in the RAS patient frame (+x toward
    the patient's right, +y anterior, +z superior).
    """

    __slots__ = ("_native",)

    def __init__(self, native: "_native.Volume") -> None:
        if not isinstance(native, _native.Volume):
            raise TypeError(
                "Volume is made by splatscene.load_volume, Volume.from_array, "
                "Volume.from_sitk or Volume.from_nibabel"
            )
        self._native = native

    @classmethod
    def from_array(
        cls,
        array: np.ndarray,
        spacing: Sequence[float] = (1.0, 1.0, 1.0),
        origin: Sequence[float] = (0.0, 0.0, 0.0),
        direction: Optional[Any] = None,
        axes: str = "zyx",
    ) -> "Volume":
        """A volume from a 3-D numpy array of real numbers.

        ``axes="zyx"`` (SimpleITK's order) takes a C-contiguous array shaped (z, y, x);
        ``axes="xyz"`` (nibabel's) a Fortran-contiguous one shaped (x, y, z). uint8, int8,
        uint16 and int16 are kept as they are, other real types become float32 (the values
        are copied). ``spacing`` (mm, positive), ``origin`` (the RAS position of voxel 0, 0, 0)
        and ``direction`` (3x3, orthonormal, columns the x, y, z axes in RAS) place it.
        """
        return cls(_native.Volume.from_array(array, spacing, origin, direction, axes))

    @classmethod
    def from_sitk(cls, image: Any) -> "Volume":
        """A volume from a SimpleITK image (taken by its methods, so SimpleITK is no
        dependency): its LPS origin and direction turned to RAS, as the file loaders do."""
        for method in ("GetSpacing", "GetOrigin", "GetDirection", "GetDimension"):
            if not callable(getattr(image, method, None)):
                raise TypeError(f"from_sitk: {type(image).__name__} has no {method}(); expected a SimpleITK image")
        if image.GetDimension() != 3:
            raise ValueError(f"from_sitk: a {image.GetDimension()}-D image; a volume is 3-D")
        components = getattr(image, "GetNumberOfComponentsPerPixel", lambda: 1)()
        if components != 1:
            raise ValueError(f"from_sitk: {components} components a pixel; a volume holds one value a voxel")
        module = sys.modules.get(type(image).__module__.split(".")[0])
        to_array = getattr(module, "GetArrayViewFromImage", None) or getattr(module, "GetArrayFromImage", None)
        if to_array is None:
            raise TypeError("from_sitk: cannot find SimpleITK's GetArrayFromImage for this image")
        array = np.ascontiguousarray(to_array(image))
        lps_to_ras = np.diag([-1.0, -1.0, 1.0])
        direction = lps_to_ras @ np.asarray(image.GetDirection(), dtype=float).reshape(3, 3)
        origin = lps_to_ras @ np.asarray(image.GetOrigin(), dtype=float)
        return cls.from_array(array, tuple(image.GetSpacing()), tuple(origin), direction, "zyx")

    @classmethod
    def from_nibabel(cls, img: Any, frame: Optional[int] = None) -> "Volume":
        """A volume from a nibabel image (NIfTI, Analyze, MGH...; taken by its ``affine`` and
        ``dataobj``, so nibabel is no dependency), placed by its affine (the sform where set,
        as nibabel chooses), values scaled as nibabel scales them. Of a 4-D image, ``frame``
        (0 by default)."""
        if not hasattr(img, "affine") or not hasattr(img, "dataobj"):
            raise TypeError(f"from_nibabel: {type(img).__name__} has no affine and dataobj; expected a nibabel image")
        affine = np.asarray(img.affine, dtype=float)
        if affine.shape != (4, 4) or not np.all(np.isfinite(affine)):
            raise ValueError("from_nibabel: the image's affine is not a finite 4x4 matrix")
        data = np.asanyarray(img.dataobj)
        if data.ndim == 4:
            chosen = 0 if frame is None else int(frame)
            if not 0 <= chosen < data.shape[3]:
                raise ValueError(f"from_nibabel: frame {chosen}; the image has {data.shape[3]} frames, counted from 0")
            if frame is None and data.shape[3] > 1:
                print(f"4-D image with {data.shape[3]} frames; frame 0 is drawn (frame=N picks another)", file=sys.stderr)
            data = data[..., chosen]
        elif frame not in (None, 0):
            raise ValueError(f"from_nibabel: frame {frame} of a {data.ndim}-D image")
        if data.ndim != 3:
            raise ValueError(f"from_nibabel: a {data.ndim}-D image; a volume is 3-D")
        linear = affine[:3, :3]
        spacing = np.linalg.norm(linear, axis=0)
        if np.any(spacing <= 0):
            raise ValueError("from_nibabel: the affine flattens an axis (a zero column)")
        return cls.from_array(np.asfortranarray(data), tuple(spacing), tuple(affine[:3, 3]), linear / spacing, "xyz")

    @property
    def array(self) -> np.ndarray:
        """The values, read-only, shaped (z, y, x), in the type the file stored; not a copy."""
        return self._native.array

    @property
    def dims(self) -> Tuple[int, int, int]:
        """Voxels along x, y and z."""
        return self._native.dims

    @property
    def spacing(self) -> Tuple[float, float, float]:
        """Millimetres between voxel centres along x, y and z."""
        return self._native.spacing

    @property
    def origin(self) -> Tuple[float, float, float]:
        """The RAS position of voxel (0, 0, 0), in millimetres."""
        return self._native.origin

    @property
    def direction(self) -> np.ndarray:
        """3x3: the columns are the x, y and z index axes in RAS."""
        return self._native.direction

    @property
    def affine(self) -> np.ndarray:
        """4x4: voxel index (x, y, z, 1) to RAS millimetres, as nibabel's ``affine``."""
        return self._native.affine

    @property
    def frame(self) -> int:
        """The 3-D frame read from a 4-D file (0 for a 3-D one)."""
        return self._native.frame

    @property
    def format(self) -> Optional[str]:
        """The file's format, None for an array."""
        return self._native.format

    @property
    def scalar_type(self) -> Optional[str]:
        """The value type the file stored, where known."""
        return self._native.scalar_type

    @property
    def path(self) -> Optional[str]:
        """The file read, None for an array."""
        return self._native.path

    def info(self) -> dict:
        """The volume described as ``splatscene info`` describes its file."""
        return self._native.info()

    def __repr__(self) -> str:
        return repr(self._native)


def load_volume(path: PathLike, **options: Any) -> Volume:
    """Reads a volume file of any format the command line reads (NRRD, NIfTI, DICOM file or
    folder, MetaImage, VTK, Voreen .dat, raw). Options as on the command line: ``series``,
    ``skip_unreadable``, ``frame``, ``nifti_transform``, ``coordinate_frame``; for a headerless
    raw file ``dims`` and ``scalar`` with ``header_bytes``, ``spacing``, ``origin`` and
    ``orientation``."""
    return Volume(_native.load_volume(path, **options))


class Mesh:
    """A triangle mesh (an implant, a bone surface) with its placement in a scene."""

    __slots__ = ("_native",)

    def __init__(self, native: "_native.Mesh") -> None:
        if not isinstance(native, _native.Mesh):
            raise TypeError("Mesh is made by Mesh.from_file or Mesh.from_arrays")
        self._native = native

    @classmethod
    def from_file(cls, path: PathLike, **options: Any) -> "Mesh":
        """Reads a glTF, GLB, OBJ or STL file (``"builtin:prosthesis"``: the generated humeral
        stem). Options: ``units`` (mm, cm or m), ``frame`` (RAS, or LPS as 3D Slicer exports),
        ``name``, ``color`` (RGB or RGBA from 0 to 1), ``opacity``, and the placement:
        ``translate`` (mm), ``rotate_degrees`` (about x, then y, then z), ``scale``, or a 4x4
        ``matrix`` alone."""
        return cls(_native.Mesh.from_file(path, **options))

    @classmethod
    def from_arrays(cls, vertices: Any, faces: Any, **options: Any) -> "Mesh":
        """A mesh from ``vertices`` (n x 3, RAS millimetres) and ``faces`` (m x 3 vertex
        indices), with the options of ``from_file`` but units and frame."""
        return cls(_native.Mesh.from_arrays(vertices, faces, **options))

    def placed(self, **placement: Any) -> "Mesh":
        """This mesh placed anew (``translate``, ``rotate_degrees``, ``scale``, or ``matrix``)."""
        return Mesh(self._native.placed(**placement))

    @property
    def name(self) -> Optional[str]:
        """The mesh's name in a scene."""
        return self._native.name

    @property
    def vertices(self) -> np.ndarray:
        """n x 3 float32, in the file's coordinates."""
        return self._native.vertices

    @property
    def faces(self) -> np.ndarray:
        """m x 3 uint32 indices into ``vertices``."""
        return self._native.faces

    def __repr__(self) -> str:
        return repr(self._native)


def _native_of(items: Optional[Iterable[Any]], kind: type) -> Optional[list]:
    if items is None:
        return None
    if isinstance(items, (str, bytes, kind)):
        raise TypeError(f"expected a list of {kind.__name__} objects or paths")
    return [getattr(item, "_native") if isinstance(item, kind) else item for item in items]


class Scene:
    """A planning scene: volumes and meshes, a camera, lights, clip planes and measurements,
    drawn as ``splatscene render`` draws it. A scene keeps its renderer, so each volume is
    classified once per transfer function across calls."""

    __slots__ = ("_native",)

    def __init__(
        self,
        volumes: Optional[Iterable[Union[Volume, PathLike]]] = None,
        meshes: Optional[Iterable[Union[Mesh, PathLike]]] = None,
        **options: Any,
    ) -> None:
        """A scene of ``volumes`` (Volume objects or paths) and ``meshes`` (Mesh objects or
        paths). Options: ``transfer`` (a preset: ct-bone, ct-soft-tissue, ct-metal,
        mr-default; "ramp" with ``window``; "auto", the default), ``window`` (lo, hi),
        ``shift``, ``crop_box`` ((x0, y0, z0), (x1, y1, z1)) with ``clip_meshes``,
        ``background`` (linear RGB) or ``transparent``, ``size`` and ``ordering`` (defaults
        of ``render``), ``view`` (the camera: "anterior" by default)."""
        self._native = _native.Scene(_native_of(volumes, Volume), _native_of(meshes, Mesh), **options)

    @classmethod
    def from_file(cls, path: PathLike) -> "Scene":
        """Reads a scene file (TOML) and what it names, as ``splatscene render FILE`` does."""
        scene = cls.__new__(cls)
        scene._native = _native.Scene.from_file(path)
        return scene

    def render(self, size: Optional[Tuple[int, int]] = None, **options: Any) -> Union[Image, Tuple[Image, np.ndarray]]:
        """The picture ``splatscene render`` draws: ``size`` (width, height; the scene's, else
        800 x 600); the camera: ``view`` (a named view such as "anterior", "left",
        "anterolateral-right", or "scene"), or ``eye`` and ``target``; ``orbit`` (yaw, pitch
        in degrees), ``fov`` or ``orthographic`` (a height in mm); ``ordering``; ``annotate``
        (True, or parts "marker,letters,scale,measurements") and ``caption``; ``lod``;
        ``transparent``. With ``depth=True`` returns ``(image, depth)``: the depth in mm along
        the view axis, float32, NaN where nothing was hit (``depth_mode`` "mesh" or
        "surface", ``surface_opacity``)."""
        out = self._native.render(size, **options)
        if isinstance(out, tuple):
            return Image(out[0]), out[1]
        return Image(out)

    def pick(self, pixel: Tuple[int, int], size: Optional[Tuple[int, int]] = None, **options: Any) -> dict:
        """The point under ``pixel`` (x, y from the top left) of the picture ``render`` draws
        with the same ``size`` and camera options, as ``splatscene pick`` reports it; options
        ``opacity`` (what a voxel must exceed to be hit) and ``meshes_only``."""
        return self._native.pick(pixel, size, **options)

    def contact(self, mesh: Optional[Union[str, Mesh]] = None, classes: Optional[Sequence[float]] = None) -> dict:
        """What a mesh's surface touches in the first volume, as ``splatscene contact``
        reports it: ``mesh`` a mesh of the scene, by name or the Mesh it was built from (the
        first by default); ``classes`` value edges (CT classes by default)."""
        name = mesh.name if isinstance(mesh, Mesh) else mesh
        return self._native.contact(name, classes=None if classes is None else list(classes))

    @property
    def size(self) -> Optional[Tuple[int, int]]:
        """The scene's own image size, None where it sets none."""
        return self._native.size

    @property
    def volumes(self) -> list:
        """The names of the scene's volumes."""
        return self._native.volumes

    @property
    def meshes(self) -> list:
        """The names of the scene's meshes."""
        return self._native.meshes

    @property
    def camera(self) -> dict:
        """The scene's camera: eye, target and up in RAS millimetres."""
        return self._native.camera

    @property
    def report(self) -> Optional[dict]:
        """What the last ``render`` drew and where its time went (splats, level of detail,
        volumes classified: 0 when the renderer kept them, the stages' milliseconds)."""
        return self._native.report

    def __repr__(self) -> str:
        return repr(self._native)


def order(dims: Sequence[int], eye: Sequence[float], ordering: str = "ip-pbtf", **options: Any) -> np.ndarray:
    """The draw order of a dense grid, as ``splatscene order`` writes it: uint32 voxel ids
    ``x + nx * (y + ny * z)``, farthest first, for an ``eye`` in voxel index coordinates.
    Options: ``spacing``, ``target``, ``cull_behind_eye``, ``bucket_width``."""
    if len(dims) != 3:
        raise ValueError(f"dims: expected three sizes (x, y, z), got {len(dims)}")
    nx, ny, nz = (int(d) for d in dims)
    return _native.order((nx, ny, nz), eye, ordering, **options)


def error(volume: Volume, eye: Sequence[float], **options: Any) -> list:
    """Each ordering's image error against the exact order for one view of ``volume``, as
    the orderings report measures it; one dict an ordering. Options: ``target``,
    ``orderings`` (names; all by default), ``size``, ``transfer`` and ``window``."""
    if not isinstance(volume, Volume):
        raise TypeError("error: volume must be a splatscene.Volume")
    return _native.error(volume._native, eye, **options)
