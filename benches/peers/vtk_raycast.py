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


def volume_property(name):
    spec = VOLUMES[name]
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
    return prop


def fitted_camera(dims, spacing):
    """Eye, focal point and distance of the project's fitted camera (aspect 1, as frame.rs)."""
    hi = [(n - 1) * s for n, s in zip(dims, spacing)]
    centre = [0.5 * h for h in hi]
    radius = 0.5 * math.sqrt(sum(h * h for h in hi))
    length = math.sqrt(sum(d * d for d in DIRECTION))
    forward = [d / length for d in DIRECTION]
    distance = radius / math.sin(math.radians(0.5 * FOV_Y_DEGREES)) * 1.02
    eye = [c - f * distance for c, f in zip(centre, forward)]
    return eye, centre, distance


def turned(eye, centre, degrees):
    """`eye` turned about the view up (+z) through `centre`, as SceneCamera::orbit(degrees, 0)."""
    a = math.radians(degrees)
    dx, dy, dz = (e - c for e, c in zip(eye, centre))
    return [
        centre[0] + dx * math.cos(a) - dy * math.sin(a),
        centre[1] + dx * math.sin(a) + dy * math.cos(a),
        centre[2] + dz,
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


def run_one(name, kind, image, args, size):
    window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetSize(*size)
    window.SetMultiSamples(0)
    renderer = vtkRenderer()
    renderer.SetBackground(0.0, 0.0, 0.0)
    window.AddRenderer(renderer)

    prop = volume_property(name)
    mapper = make_mapper(kind, args)
    mapper.SetInputData(image)
    volume = vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    renderer.AddVolume(volume)

    dims = image.GetDimensions()
    eye, centre, distance = fitted_camera(dims, image.GetSpacing())
    camera = renderer.GetActiveCamera()
    camera.SetParallelProjection(0)
    camera.SetViewAngle(FOV_Y_DEGREES)  # vertical (UseHorizontalViewAngle is off)
    camera.SetFocalPoint(*centre)
    camera.SetViewUp(*VIEW_UP)

    def place(degrees):
        camera.SetPosition(*turned(eye, centre, degrees))
        camera.SetFocalPoint(*centre)
        camera.SetViewUp(*VIEW_UP)
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
        path = os.path.join(args.save, f"{name}_{kind}.png")
        copy = vtkImageData()
        copy.DeepCopy(first)
        writer = vtkPNGWriter()
        writer.SetFileName(path)
        writer.SetInputData(copy)
        writer.Write()
        info["png"] = path

    times = []
    for i in range(1, args.frames + 1):
        place(TURN_DEGREES * i)
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


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--volumes", default="engine,cthead", help="comma-separated: engine,cthead")
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
    p.add_argument("--save", metavar="DIR", help="write the first (untimed) frame of each as PNG")
    args = p.parse_args()
    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
        assert w > 0 and h > 0
    except (ValueError, AssertionError):
        p.error("--size must be WxH, e.g. 512x512")
    args.size_wh = (w, h)
    if args.frames < 1:
        p.error("--frames must be at least 1")
    args.volume_list = [v.strip() for v in args.volumes.split(",") if v.strip()]
    args.mapper_list = [m.strip() for m in args.mappers.split(",") if m.strip()]
    for v in args.volume_list:
        if v not in VOLUMES:
            p.error(f"unknown volume {v!r} (engine, cthead)")
    for m in args.mapper_list:
        if m not in ("fixed", "gpu"):
            p.error(f"unknown mapper {m!r} (fixed, gpu)")
    return args


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
        "turn_degrees_per_frame": TURN_DEGREES,
        "sample_distance": args.sample_distance,
        "timing": "renWin.Render() plus vtkWindowToImageFilter readback per frame; warm-up render excluded",
        "cpu_count": os.cpu_count(),
        "results": {},
    }
    rows = []
    for name in args.volume_list:
        values, spacing = load_volume(name)
        image = image_data(values, spacing)
        report["results"][name] = {}
        for kind in args.mapper_list:
            info = run_one(name, kind, image, args, args.size_wh)
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

    print(file=sys.stderr)
    print(f"{'volume':<8} {'mapper':<6} {'frames':>6} {'median ms':>10} {'min ms':>9}", file=sys.stderr)
    for name, kind, info in rows:
        print(
            f"{name:<8} {kind:<6} {info['frames']:>6} {info['median_ms']:>10.1f} {info['min_ms']:>9.1f}",
            file=sys.stderr,
        )
    json.dump(report, sys.stdout, indent=2)
    print()


if __name__ == "__main__":
    main()
