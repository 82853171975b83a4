#!/usr/bin/env python3
"""Peer benchmark: the engine and the CT head drawn by VTK's ray casters.

Renders the volume views of `benches/frame.rs` (same data, transfer functions and fitted
camera, the camera turning 7 degrees a frame about the view up) offscreen with

  fixed  vtkFixedPointVolumeRayCastMapper  (CPU ray casting with space leaping and early ray
                                            termination, multithreaded)
  gpu    vtkGPUVolumeRayCastMapper         (OpenGL ray casting; on a machine without a GPU it
                                            runs on Mesa's llvmpipe, i.e. on the CPU too)

and times whole frames: renWin.Render() followed by a readback of the image to the CPU
(vtkWindowToImageFilter), so each frame is finished when it is timed. The first render of
each (volume, mapper) is a warm-up and is not timed (it uploads the volume and, for the CPU
mapper, computes the gradients).

With `--raw` it draws a headerless raw volume instead (any size and scalar type, placed in the
world by `--spacing`, `--orientation` and `--origin` as `splatscene render` places it), with a
ramp transfer function (`--window`, `--color`, `--alpha`) and an explicit camera (`--eye`,
`--target`, `--fov`, `--up`), so that its frames can be compared with `splatscene render` on the
same picture.

Prints a JSON object on stdout and a table on stderr. Exits non-zero when VTK or an offscreen
OpenGL context is not available.

Offscreen GL: the PyPI `vtk` wheel (9.4 and later) picks its render window at run time. This
script asks for OSMesa (`VTK_DEFAULT_OPENGL_WINDOW=vtkOSOpenGLRenderWindow`, needs Debian's
`libosmesa6`) unless the variable is already set; set it to `vtkEGLRenderWindow` to render
through EGL instead (e.g. on a machine with a GPU driver).

Data: `$SPLATSCENE_DATA/volumes/...` (default `../shared/data`, relative to the current
directory), as in the project's benchmarks.
"""

import argparse
import json
import math
import os
import statistics
import sys
import time

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkOSOpenGLRenderWindow")


def die(message, code=2):
    print(f"vtk_raycast: {message}", file=sys.stderr)
    sys.exit(code)


try:
    import numpy as np
except ImportError:
    die("numpy is not installed (pip install numpy)")

try:
    import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (OpenGL factory overrides)
    import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401  (GPU volume mapper)
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonCore import vtkMultiThreader, vtkOutputWindow, vtkVersion
    from vtkmodules.vtkCommonMath import vtkMatrix4x4
    from vtkmodules.vtkCommonDataModel import vtkImageData, vtkPiecewiseFunction
    from vtkmodules.vtkIOImage import vtkPNGWriter
    from vtkmodules.vtkRenderingCore import (
        vtkColorTransferFunction,
        vtkRenderer,
        vtkRenderWindow,
        vtkVolume,
        vtkVolumeProperty,
        vtkWindowToImageFilter,
    )
    from vtkmodules.vtkRenderingVolume import (
        vtkFixedPointVolumeRayCastMapper,
        vtkGPUVolumeRayCastMapper,
    )
except ImportError as e:
    die(f"VTK is not available ({e}); install it with: pip install vtk")

# Keep stdout for the JSON report.
vtkOutputWindow.GetInstance().SetDisplayModeToAlwaysStdErr()

# The views of benches/frame.rs: (file spec, spacing, transfer function).
# Transfer function: linear opacity ramp from 0 at `lo` to `alpha` at `hi` and above, constant
# colour, as TransferFunction::ramp(lo, hi, [r, g, b, alpha]).
VOLUMES = {
    "engine": dict(
        spacing=(1.0, 1.0, 1.0),
        ramp=(100.0, 200.0),
        rgba=(0.85, 0.8, 0.75, 0.5),
    ),
    "cthead": dict(
        spacing=(1.0, 1.0, 2.0),
        ramp=(1200.0, 1800.0),
        rgba=(1.0, 0.93, 0.85, 0.6),
    ),
}

# Camera of SceneCamera::fit in the project: 35 degree vertical field of view, looking along
# DIRECTION at the centre of the voxel-centre bounds, from radius / sin(half angle) * 1.02.
FOV_Y_DEGREES = 35.0
DIRECTION = (-0.4, 1.0, -0.55)
VIEW_UP = (0.0, 0.0, 1.0)
TURN_DEGREES = 7.0

# Raw volumes (--raw): scalar names as splatscene takes them, all little-endian.
RAW_SCALARS = {"u8": np.dtype("u1"), "u16": np.dtype("<u2"), "i16": np.dtype("<i2")}
# Patient directions in the RAS world frame (+x right, +y anterior, +z superior).
LETTERS = {
    "R": (1.0, 0.0, 0.0),
    "L": (-1.0, 0.0, 0.0),
    "A": (0.0, 1.0, 0.0),
    "P": (0.0, -1.0, 0.0),
    "S": (0.0, 0.0, 1.0),
    "I": (0.0, 0.0, -1.0),
}
DEFAULT_RAW_COLOR = (1.0, 0.93, 0.85)
DEFAULT_RAW_ALPHA = 0.6


def data_dir():
    return os.path.join(os.environ.get("SPLATSCENE_DATA", os.path.join("..", "shared", "data")), "volumes")


def load_volume(name):
    """The volume as a (nz, ny, nx) array (x fastest in memory) and its spacing."""
    root = data_dir()
    if name == "engine":
        path = os.path.join(root, "engine", "engine_256x256x128_uint8.raw")
        try:
            raw = np.fromfile(path, dtype=np.uint8)
        except OSError as e:
            die(f"cannot read the engine volume ({e}); set SPLATSCENE_DATA")
        if raw.size != 256 * 256 * 128:
            die(f"{path}: expected {256 * 256 * 128} bytes, found {raw.size}")
        values = raw.reshape(128, 256, 256)
    elif name == "cthead":
        slices = []
        for k in range(1, 114):
            path = os.path.join(root, "stanford_cthead", f"CThead.{k}")
            try:
                s = np.fromfile(path, dtype=">u2")
            except OSError as e:
                die(f"cannot read the CT head ({e}); set SPLATSCENE_DATA")
            if s.size != 256 * 256:
                die(f"{path}: expected {256 * 256} big-endian u16 values, found {s.size}")
            slices.append(s.reshape(256, 256))
        values = np.stack(slices).astype(np.uint16)  # native byte order
    else:
        die(f"unknown volume {name!r}")
    return np.ascontiguousarray(values), VOLUMES[name]["spacing"]


def load_raw(path, dims, scalar):
    """A headerless little-endian raw volume, x fastest, as a (nz, ny, nx) array."""
    dtype = RAW_SCALARS[scalar]
    nx, ny, nz = dims
    expected = nx * ny * nz
    try:
        size = os.path.getsize(path)
    except OSError as e:
        die(f"cannot read {path} ({e})")
    if size != expected * dtype.itemsize:
        die(
            f"{path}: {nx}x{ny}x{nz} {scalar} needs {expected * dtype.itemsize} bytes, "
            f"the file has {size}"
        )
    values = np.fromfile(path, dtype=dtype)
    # VTK takes native byte order.
    values = values.astype(dtype.newbyteorder("="), copy=False)
    return np.ascontiguousarray(values.reshape(nz, ny, nx))


def direction_matrix(code):
    """The 3x3 matrix (rows) whose columns are the unit vectors of the three letters."""
    columns = [LETTERS[c] for c in code]
    return [[columns[j][i] for j in range(3)] for i in range(3)]


def user_matrix(direction, origin):
    """world = origin + direction * (spacing * index): the vtkImageData applies the spacing, this
    matrix the rest."""
    m = vtkMatrix4x4()
    m.Identity()
    for i in range(3):
        for j in range(3):
            m.SetElement(i, j, direction[i][j])
        m.SetElement(i, 3, origin[i])
    return m


def world_corners(dims, spacing, direction, origin):
    """The eight corners of the voxel-centre box in world coordinates."""
    corners = []
    for cx in (0, dims[0] - 1):
        for cy in (0, dims[1] - 1):
            for cz in (0, dims[2] - 1):
                local = (cx * spacing[0], cy * spacing[1], cz * spacing[2])
                corners.append(
                    [origin[i] + sum(direction[i][j] * local[j] for j in range(3)) for i in range(3)]
                )
    return corners


def image_data(values, spacing):
    nz, ny, nx = values.shape
    image = vtkImageData()
    image.SetDimensions(nx, ny, nz)
    image.SetSpacing(*spacing)
    image.SetOrigin(0.0, 0.0, 0.0)
    array = numpy_support.numpy_to_vtk(values.ravel(order="C"), deep=True)
    array.SetName("values")
    image.GetPointData().SetScalars(array)
    return image


def volume_property(spec, opacity_unit_distance):
    lo, hi = spec["ramp"]
    r, g, b, alpha = spec["rgba"]
    colour = vtkColorTransferFunction()
    colour.AddRGBPoint(lo, r, g, b)
    colour.AddRGBPoint(hi, r, g, b)
    opacity = vtkPiecewiseFunction()
    # Clamping (on by default) holds 0 below `lo` and `alpha` above `hi`.
    opacity.AddPoint(lo, 0.0)
    opacity.AddPoint(hi, alpha)
    prop = vtkVolumeProperty()
    prop.SetColor(colour)
    prop.SetScalarOpacity(opacity)
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOn()
    prop.SetScalarOpacityUnitDistance(opacity_unit_distance)
    return prop


def fitted_camera(corners, fov_degrees=FOV_Y_DEGREES):
    """Eye and focal point of the project's fitted camera (aspect 1, as frame.rs) for the box of
    the given world corners."""
    lo = [min(c[i] for c in corners) for i in range(3)]
    hi = [max(c[i] for c in corners) for i in range(3)]
    centre = [0.5 * (a + b) for a, b in zip(lo, hi)]
    radius = 0.5 * math.sqrt(sum((b - a) ** 2 for a, b in zip(lo, hi)))
    length = math.sqrt(sum(d * d for d in DIRECTION))
    forward = [d / length for d in DIRECTION]
    distance = radius / math.sin(math.radians(0.5 * fov_degrees)) * 1.02
    eye = [c - f * distance for c, f in zip(centre, forward)]
    return eye, centre


def turned(eye, centre, degrees, up=VIEW_UP):
    """`eye` turned by `degrees` about the axis `up` through `centre` (right-handed), as
    SceneCamera::orbit(degrees, 0) turns it about +z."""
    a = math.radians(degrees)
    length = math.sqrt(sum(u * u for u in up))
    k = [u / length for u in up]
    v = [e - c for e, c in zip(eye, centre)]
    cos, sin = math.cos(a), math.sin(a)
    kv = sum(ki * vi for ki, vi in zip(k, v))
    cross = [k[1] * v[2] - k[2] * v[1], k[2] * v[0] - k[0] * v[2], k[0] * v[1] - k[1] * v[0]]
    # Rodrigues' rotation formula.
    return [
        c + vi * cos + ci * sin + ki * kv * (1.0 - cos)
        for c, vi, ci, ki in zip(centre, v, cross, k)
    ]


def make_mapper(kind, args):
    if kind == "fixed":
        mapper = vtkFixedPointVolumeRayCastMapper()
        if args.threads:
            mapper.SetNumberOfThreads(args.threads)
    elif kind == "gpu":
        mapper = vtkGPUVolumeRayCastMapper()
    else:
        die(f"unknown mapper {kind!r} (fixed, gpu)")
    # Fixed sampling for a steady workload: no adaptation to a desired frame rate.
    mapper.AutoAdjustSampleDistancesOff()
    mapper.SetSampleDistance(args.sample_distance)
    mapper.SetImageSampleDistance(1.0)
    return mapper


def gl_renderer_string(window):
    report = window.ReportCapabilities() or ""
    for line in report.splitlines():
        if "OpenGL renderer string" in line:
            return line.split(":", 1)[1].strip()
    return None


def grab(window, w2i):
    w2i.Modified()
    w2i.Update()
    return w2i.GetOutput()


def to_numpy(image):
    w, h, _ = image.GetDimensions()
    scalars = image.GetPointData().GetScalars()
    return numpy_support.vtk_to_numpy(scalars).reshape(h, w, -1)


def run_one(spec, kind, image, args, size):
    window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetSize(*size)
    window.SetMultiSamples(0)
    renderer = vtkRenderer()
    renderer.SetBackground(0.0, 0.0, 0.0)
    window.AddRenderer(renderer)

    name = spec["name"]
    prop = volume_property(spec, args.opacity_unit_distance)
    mapper = make_mapper(kind, args)
    mapper.SetInputData(image)
    volume = vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    if spec.get("matrix") is not None:
        volume.SetUserMatrix(spec["matrix"])
    renderer.AddVolume(volume)

    eye, centre = spec["eye"], spec["target"]
    up, fov, turn = spec["up"], spec["fov"], spec["turn"]
    distance = math.sqrt(sum((e - c) ** 2 for e, c in zip(eye, centre)))
    camera = renderer.GetActiveCamera()
    camera.SetParallelProjection(0)
    camera.SetViewAngle(fov)  # vertical (UseHorizontalViewAngle is off)
    camera.SetFocalPoint(*centre)
    camera.SetViewUp(*up)

    def place(degrees):
        camera.SetPosition(*turned(eye, centre, degrees, up))
        camera.SetFocalPoint(*centre)
        camera.SetViewUp(*up)
        renderer.ResetCameraClippingRange()

    w2i = vtkWindowToImageFilter()
    w2i.SetInput(window)
    w2i.SetInputBufferTypeToRGB()
    w2i.ReadFrontBufferOff()
    w2i.ShouldRerenderOff()

    # Warm-up: the fitted view, not timed.
    place(0.0)
    t0 = time.perf_counter()
    window.Render()
    first = grab(window, w2i)
    warmup_ms = (time.perf_counter() - t0) * 1e3

    info = {
        "gl_renderer": gl_renderer_string(window),
        "render_window": window.GetClassName(),
        "mapper_class": mapper.GetClassName(),
        "eye": [round(v, 4) for v in eye],
        "focal_point": [round(v, 4) for v in centre],
        "view_up": [round(v, 4) for v in up],
        "view_angle": fov,
        "turn_degrees_per_frame": turn,
        "distance": round(distance, 4),
        "clipping_range": [round(v, 3) for v in camera.GetClippingRange()],
        "scalar_opacity_unit_distance": prop.GetScalarOpacityUnitDistance(),
        "sample_distance": mapper.GetSampleDistance(),
        "warmup_ms": round(warmup_ms, 2),
    }
    if kind == "fixed":
        info["threads"] = mapper.GetNumberOfThreads()
    else:
        info["render_supported"] = bool(mapper.IsRenderSupported(window, prop))

    pixels = to_numpy(first)
    info["lit_fraction"] = round(float((pixels.max(axis=2) > 0).mean()), 4)
    if args.save:
        os.makedirs(args.save, exist_ok=True)
        path = os.path.join(args.save, f"{spec['file_stem']}_{kind}.png")
        copy = vtkImageData()
        copy.DeepCopy(first)
        writer = vtkPNGWriter()
        writer.SetFileName(path)
        writer.SetInputData(copy)
        writer.Write()
        info["png"] = path

    times = []
    for i in range(1, args.frames + 1):
        place(turn * i)
        t0 = time.perf_counter()
        window.Render()
        grab(window, w2i)
        times.append((time.perf_counter() - t0) * 1e3)

    info["frames"] = len(times)
    info["median_ms"] = round(statistics.median(times), 2) if times else None
    info["min_ms"] = round(min(times), 2) if times else None
    info["frame_ms"] = [round(t, 2) for t in times]

    renderer.RemoveVolume(volume)
    window.Finalize()
    return info


def check_offscreen_gl():
    """Exits non-zero unless an offscreen OpenGL context can be made; returns its strings."""
    window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetSize(16, 16)
    renderer = vtkRenderer()
    window.AddRenderer(renderer)
    supports = getattr(window, "SupportsOpenGL", None)
    if supports is not None and not supports():
        die(
            f"{window.GetClassName()} cannot create an offscreen OpenGL context "
            "(for OSMesa: apt-get install libosmesa6; or set "
            "VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow)"
        )
    window.Render()
    renderer_string = gl_renderer_string(window)
    if not renderer_string:
        die(f"{window.GetClassName()}: no OpenGL renderer string; offscreen GL is not working")
    name = window.GetClassName()
    window.Finalize()
    return name, renderer_string


# Options whose value may start with '-' (a negative coordinate): argparse of Python 3.11 would
# take "-179.3,879.3,-165" for an option, so these are joined to their value with '='.
VALUE_OPTIONS = ("--eye", "--target", "--up", "--origin", "--spacing", "--window", "--color")


def join_values(argv):
    out = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in VALUE_OPTIONS and i + 1 < len(argv):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
        else:
            out.append(a)
            i += 1
    return out


def parse_floats(p, option, text, n):
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != n or not all(math.isfinite(v) for v in values):
        p.error(f"{option} takes {n} comma-separated numbers, not {text!r}")
    return values


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--volumes",
        default=None,
        help="comma-separated: engine,cthead (default both; not with --raw)",
    )
    p.add_argument("--mappers", default="fixed,gpu", help="comma-separated: fixed,gpu")
    p.add_argument("--frames", type=int, default=20, help="timed frames per (volume, mapper)")
    p.add_argument("--size", default="512x512", help="image size WxH")
    p.add_argument(
        "--threads",
        type=int,
        default=0,
        help="threads for the CPU mapper (vtkMultiThreader); 0 = VTK's choice",
    )
    p.add_argument(
        "--sample-distance",
        type=float,
        default=0.5,
        help="ray sample distance in world units for both mappers (default 0.5)",
    )
    p.add_argument(
        "--opacity-unit-distance",
        type=float,
        default=1.0,
        metavar="MM",
        help="vtkVolumeProperty scalar opacity unit distance in world units (default 1.0)",
    )
    p.add_argument("--save", metavar="DIR", help="write the first (untimed) frame of each as PNG")

    raw = p.add_argument_group("raw volume (instead of --volumes)")
    raw.add_argument("--raw", metavar="PATH", help="headerless little-endian raw volume, x fastest")
    raw.add_argument("--dims", metavar="X,Y,Z", help="grid size in voxels")
    raw.add_argument("--scalar", choices=sorted(RAW_SCALARS), help="voxel type")
    raw.add_argument("--spacing", metavar="SX,SY,SZ", help="voxel spacing in world units (mm)")
    raw.add_argument(
        "--orientation",
        metavar="CODE",
        help="where index axes x, y, z run in the RAS world, e.g. LAI (default RAS)",
    )
    raw.add_argument("--origin", metavar="X,Y,Z", help="world position of voxel (0,0,0) (default 0,0,0)")
    raw.add_argument(
        "--window",
        metavar="LO,HI",
        help="opacity ramps linearly from 0 at LO to --alpha at HI and above",
    )
    raw.add_argument(
        "--color",
        metavar="R,G,B",
        help="constant colour, 0..1 (default %s)" % ",".join(str(v) for v in DEFAULT_RAW_COLOR),
    )
    raw.add_argument(
        "--alpha",
        type=float,
        default=None,
        help=f"opacity at HI and above (default {DEFAULT_RAW_ALPHA})",
    )

    cam = p.add_argument_group("camera (any volume; default: the fitted camera of frame.rs)")
    cam.add_argument("--eye", metavar="X,Y,Z", help="camera position in world units")
    cam.add_argument("--target", metavar="X,Y,Z", help="focal point (with --eye)")
    cam.add_argument(
        "--fov",
        type=float,
        default=FOV_Y_DEGREES,
        metavar="DEG",
        help=f"vertical view angle in degrees (default {FOV_Y_DEGREES:g})",
    )
    cam.add_argument("--up", metavar="X,Y,Z", help="view up, also the turning axis (default 0,0,1)")
    cam.add_argument(
        "--turn",
        type=float,
        default=TURN_DEGREES,
        metavar="DEG",
        help=f"degrees the camera turns per frame about --up through the target (default {TURN_DEGREES:g}; 0 = same view)",
    )

    args = p.parse_args(join_values(sys.argv[1:] if argv is None else argv))
    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
        assert w > 0 and h > 0
    except (ValueError, AssertionError):
        p.error("--size must be WxH, e.g. 512x512")
    args.size_wh = (w, h)
    if args.frames < 1:
        p.error("--frames must be at least 1")
    if not (args.sample_distance > 0):
        p.error("--sample-distance must be positive")
    if not (args.opacity_unit_distance > 0):
        p.error("--opacity-unit-distance must be positive")
    if not (0.1 <= args.fov <= 170.0):
        p.error("--fov must be from 0.1 to 170 degrees")
    if not math.isfinite(args.turn):
        p.error("--turn must be a number")
    args.mapper_list = [m.strip() for m in args.mappers.split(",") if m.strip()]
    for m in args.mapper_list:
        if m not in ("fixed", "gpu"):
            p.error(f"unknown mapper {m!r} (fixed, gpu)")

    # Camera.
    args.eye_xyz = parse_floats(p, "--eye", args.eye, 3) if args.eye else None
    args.target_xyz = parse_floats(p, "--target", args.target, 3) if args.target else None
    if (args.eye_xyz is None) != (args.target_xyz is None):
        p.error("--eye and --target go together")
    args.up_xyz = parse_floats(p, "--up", args.up, 3) if args.up else VIEW_UP
    if math.sqrt(sum(u * u for u in args.up_xyz)) < 1e-9:
        p.error("--up must not be zero")
    if args.eye_xyz is not None:
        view = [t - e for e, t in zip(args.eye_xyz, args.target_xyz)]
        length = math.sqrt(sum(v * v for v in view))
        if length < 1e-9:
            p.error("--eye and --target are the same point")
        ulen = math.sqrt(sum(u * u for u in args.up_xyz))
        cos = abs(sum(v * u for v, u in zip(view, args.up_xyz))) / (length * ulen)
        if cos > 0.9999:
            p.error("--up is parallel to the view direction")

    raw_only = ("dims", "scalar", "spacing", "orientation", "origin", "window", "color", "alpha")
    if args.raw is None:
        given = [f"--{k}" for k in raw_only if getattr(args, k) is not None]
        if given:
            p.error(f"{', '.join(given)} only apply with --raw")
        volumes = args.volumes if args.volumes is not None else "engine,cthead"
        args.volume_list = [v.strip() for v in volumes.split(",") if v.strip()]
        for v in args.volume_list:
            if v not in VOLUMES:
                p.error(f"unknown volume {v!r} (engine, cthead)")
        return args

    if args.volumes is not None:
        p.error("--volumes and --raw: give one")
    for k in ("dims", "scalar", "spacing", "window"):
        if getattr(args, k) is None:
            p.error(f"--raw needs --{k}")
    try:
        dims = tuple(int(v) for v in args.dims.split(","))
    except ValueError:
        dims = ()
    if len(dims) != 3 or min(dims) < 1:
        p.error(f"--dims takes X,Y,Z positive integers, not {args.dims!r}")
    spacing = parse_floats(p, "--spacing", args.spacing, 3)
    if min(spacing) <= 0:
        p.error("--spacing must be positive")
    code = (args.orientation or "RAS").upper()
    axes = {"R": 0, "L": 0, "A": 1, "P": 1, "S": 2, "I": 2}
    if len(code) != 3 or any(c not in axes for c in code) or sorted(axes[c] for c in code) != [0, 1, 2]:
        p.error(
            f"--orientation {args.orientation!r} is not three letters, one each from R/L, A/P and S/I"
        )
    origin = parse_floats(p, "--origin", args.origin, 3) if args.origin else (0.0, 0.0, 0.0)
    lo, hi = parse_floats(p, "--window", args.window, 2)
    if not lo < hi:
        p.error("--window needs LO < HI")
    color = parse_floats(p, "--color", args.color, 3) if args.color else DEFAULT_RAW_COLOR
    alpha = DEFAULT_RAW_ALPHA if args.alpha is None else args.alpha
    if not (0.0 <= alpha <= 1.0) or not all(0.0 <= c <= 1.0 for c in color):
        p.error("--color and --alpha take values from 0 to 1")
    args.raw_spec = dict(
        dims=dims,
        spacing=spacing,
        orientation=code,
        origin=origin,
        ramp=(lo, hi),
        rgba=(*color, alpha),
    )
    return args


def volume_spec(name, spacing, dims, args, ramp, rgba, orientation="RAS", origin=(0.0, 0.0, 0.0)):
    """Everything run_one needs about one volume besides its image: transfer function, placement
    and camera."""
    direction = direction_matrix(orientation)
    identity = orientation == "RAS" and tuple(origin) == (0.0, 0.0, 0.0)
    if args.eye_xyz is not None:
        eye, target = list(args.eye_xyz), list(args.target_xyz)
    else:
        eye, target = fitted_camera(world_corners(dims, spacing, direction, origin), args.fov)
    stem = os.path.splitext(name)[0] if args.raw else name
    return dict(
        name=name,
        file_stem="".join(c if c.isalnum() or c in "-_." else "_" for c in stem),
        ramp=ramp,
        rgba=rgba,
        matrix=None if identity else user_matrix(direction, origin),
        orientation=orientation,
        origin=list(origin),
        eye=eye,
        target=target,
        up=list(args.up_xyz),
        fov=args.fov,
        turn=args.turn,
    )


def main():
    args = parse_args()
    if args.threads:
        vtkMultiThreader.SetGlobalMaximumNumberOfThreads(args.threads)
        vtkMultiThreader.SetGlobalDefaultNumberOfThreads(args.threads)

    version = vtkVersion.GetVTKVersion()
    window_class, gl = check_offscreen_gl()
    print(f"VTK {version}; render window {window_class}; OpenGL renderer: {gl}", file=sys.stderr)
    print(
        f"CPU mapper threads: {args.threads or 'VTK default'} "
        f"(vtkMultiThreader default {vtkMultiThreader.GetGlobalDefaultNumberOfThreads()}); "
        f"llvmpipe threads: LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}",
        file=sys.stderr,
    )

    report = {
        "vtk_version": version,
        "render_window": window_class,
        "gl_renderer": gl,
        "size": list(args.size_wh),
        "frames": args.frames,
        "turn_degrees_per_frame": args.turn,
        "sample_distance": args.sample_distance,
        "scalar_opacity_unit_distance": args.opacity_unit_distance,
        "timing": "renWin.Render() plus vtkWindowToImageFilter readback per frame; warm-up render excluded",
        "cpu_count": os.cpu_count(),
        "results": {},
    }

    def volumes():
        if args.raw is None:
            for name in args.volume_list:
                values, spacing = load_volume(name)
                nz, ny, nx = values.shape
                v = VOLUMES[name]
                yield volume_spec(name, spacing, (nx, ny, nz), args, v["ramp"], v["rgba"]), values, spacing
        else:
            r = args.raw_spec
            name = os.path.basename(args.raw)
            values = load_raw(args.raw, r["dims"], args.scalar)
            spec = volume_spec(
                name, r["spacing"], r["dims"], args, r["ramp"], r["rgba"], r["orientation"], r["origin"]
            )
            report["raw"] = {
                "path": os.path.abspath(args.raw),
                "dims": list(r["dims"]),
                "scalar": args.scalar,
                "spacing": list(r["spacing"]),
                "orientation": r["orientation"],
                "origin": list(r["origin"]),
                "window": list(r["ramp"]),
                "color": list(r["rgba"][:3]),
                "alpha": r["rgba"][3],
            }
            yield spec, values, r["spacing"]

    rows = []
    for spec, values, spacing in volumes():
        name = spec["name"]
        image = image_data(values, spacing)
        del values
        report["results"][name] = {}
        for kind in args.mapper_list:
            info = run_one(spec, kind, image, args, args.size_wh)
            report["results"][name][kind] = info
            extra = (
                f"threads {info['threads']}"
                if kind == "fixed"
                else f"supported {info['render_supported']}"
            )
            print(
                f"  {name} {kind}: opacity unit distance {info['scalar_opacity_unit_distance']}, "
                f"sample distance {info['sample_distance']}, {extra}, warm-up {info['warmup_ms']:.0f} ms, "
                f"lit {100 * info['lit_fraction']:.1f}% of pixels",
                file=sys.stderr,
            )
            rows.append((name, kind, info))

    width = max([8] + [len(name) for name, _, _ in rows])
    print(file=sys.stderr)
    print(f"{'volume':<{width}} {'mapper':<6} {'frames':>6} {'median ms':>10} {'min ms':>9}", file=sys.stderr)
    for name, kind, info in rows:
        print(
            f"{name:<{width}} {kind:<6} {info['frames']:>6} {info['median_ms']:>10.1f} {info['min_ms']:>9.1f}",
            file=sys.stderr,
        )
    json.dump(report, sys.stdout, indent=2)
    print()


if __name__ == "__main__":
    main()
