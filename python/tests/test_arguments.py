"""Bad arguments give clear Python exceptions that name the argument, never a crash."""

import threading
import time

import numpy as np
import pytest

import splatscene
from conftest import REPO, data_file

GOOD = np.zeros((4, 5, 6), dtype=np.int16)


@pytest.mark.parametrize(
    "array,kwargs,error,match",
    [
        (np.zeros((4, 5, 6), dtype=np.complex64), {}, TypeError, "dtype"),
        (np.zeros((4, 5, 6), dtype=bool), {}, TypeError, "dtype"),
        (np.array([[["a"]]]), {}, TypeError, "dtype"),
        (np.zeros((4, 5, 6), dtype=object), {}, TypeError, "dtype"),
        (np.zeros((5, 6), dtype=np.int16), {}, ValueError, "3-D"),
        (np.zeros((2, 3, 4, 5), dtype=np.int16), {}, ValueError, "3-D"),
        (np.zeros((0, 5, 6), dtype=np.int16), {}, ValueError, "empty"),
        ([[[1, 2]]], {}, TypeError, "numpy array"),
        (GOOD, {"spacing": (1, float("nan"), 1)}, ValueError, "spacing"),
        (GOOD, {"spacing": (1, 0, 1)}, ValueError, "spacing"),
        (GOOD, {"spacing": (1, 1)}, ValueError, "spacing"),
        (GOOD, {"spacing": "111"}, TypeError, "spacing"),
        (GOOD, {"origin": (0, float("inf"), 0)}, ValueError, "origin"),
        (GOOD[:, :, ::2], {}, ValueError, "contiguous"),
        (GOOD.transpose(2, 1, 0), {}, ValueError, "contiguous"),
        (np.ascontiguousarray(GOOD.transpose(2, 1, 0)), {"axes": "xyz"}, ValueError, "contiguous"),
        (GOOD, {"axes": "yxz"}, ValueError, "axes"),
        (GOOD, {"direction": np.diag([1.0, 2.0, 1.0])}, ValueError, "rotation"),
        (GOOD, {"direction": [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]}, ValueError, "rotation"),
        (GOOD, {"direction": np.eye(4)}, ValueError, "direction"),
        (GOOD, {"direction": [[1, 0, 0], [0, float("nan"), 0], [0, 0, 1]]}, ValueError, "direction"),
    ],
)
def test_bad_arrays_and_placements_are_refused(array, kwargs, error, match):
    with pytest.raises(error, match=match):
        splatscene.Volume.from_array(array, **kwargs)


def test_a_mirrored_direction_is_a_scanners_grid_and_is_taken():
    v = splatscene.Volume.from_array(GOOD, direction=np.diag([-1.0, -1.0, 1.0]) @ np.diag([1.0, 1.0, -1.0]))
    assert np.allclose(v.direction, np.diag([-1.0, -1.0, -1.0]))


def test_bad_files_and_options_are_the_librarys_errors(tmp_path):
    with pytest.raises(splatscene.SplatsceneError, match="missing.nii"):
        splatscene.load_volume(tmp_path / "missing.nii")
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01" * 50)
    with pytest.raises(splatscene.SplatsceneError):
        splatscene.load_volume(junk)
    with pytest.raises(splatscene.SplatsceneError, match="bytes|size|short|expected"):
        splatscene.load_volume(junk, dims=(100, 100, 100), scalar="u8")
    with pytest.raises(ValueError, match="scalar"):
        splatscene.load_volume(junk, dims=(10, 10, 1), scalar="u9")
    with pytest.raises(ValueError, match="spacing applies to a headerless raw volume"):
        splatscene.load_volume(data_file("volumes/totalseg_ct/aorta_ct_cropped.nii.gz"), spacing=(1, 1, 1))
    with pytest.raises(splatscene.SplatsceneError, match="series"):
        splatscene.load_volume(data_file("volumes/totalseg_ct/aorta_ct_cropped.nii.gz"), series="2")
    with pytest.raises(splatscene.SplatsceneError):
        splatscene.Scene.from_file(tmp_path / "none.toml")
    with pytest.raises(splatscene.SplatsceneError):
        splatscene.Mesh.from_file(junk)


def test_grid_sizes_are_any_sequence_of_whole_numbers(tmp_path):
    raw = tmp_path / "ramp.raw"
    np.arange(4 * 3 * 2, dtype=np.uint8).tofile(raw)
    for dims in [(4, 3, 2), [4, 3, 2], np.array([4, 3, 2]), (np.int64(4), 3, 2)]:
        v = splatscene.load_volume(raw, dims=dims, scalar="u8")
        assert v.dims == (4, 3, 2)
        assert v.array.shape == (2, 3, 4)
    assert splatscene.order([3, 2, 2], (10.0, 1.0, 1.0)).shape == (12,)
    for dims, error, match in [
        ((4.5, 3, 2), TypeError, "dims: 4.5 is not a whole number"),
        ((4, -3, 2), ValueError, "dims: -3 is not a size"),
        ((4, 3), ValueError, "dims: expected 3 whole numbers, got 2"),
        ("432", TypeError, "not a string"),
        (7, TypeError, "expected 3 whole numbers"),
    ]:
        with pytest.raises(error, match=match):
            splatscene.load_volume(raw, dims=dims, scalar="u8")


def test_bad_render_arguments_are_refused():
    scene = splatscene.Scene.from_file(REPO / "examples" / "scenes" / "shoulder.toml")
    for kwargs, error, match in [
        ({"size": (0, 10)}, ValueError, "size"),
        ({"size": (10,)}, ValueError, "size"),
        ({"size": (10.5, 10)}, TypeError, "size"),
        ({"view": "sideways"}, ValueError, "view"),
        ({"view": "left", "eye": (1, 2, 3)}, ValueError, "view and eye"),
        ({"eye": (1, 2, float("nan"))}, ValueError, "eye"),
        ({"eye": (1, 2, 3), "target": (1, 2, 3)}, ValueError, "one point"),
        ({"ordering": "random"}, ValueError, "ordering"),
        ({"fov": 0.0}, ValueError, "fov"),
        ({"fov": 40.0, "orthographic": 100.0}, ValueError, "fov"),
        ({"annotate": "arrows"}, ValueError, "annotate"),
        ({"annotate": 3}, TypeError, "annotate"),
        ({"caption": "  "}, ValueError, "caption"),
        ({"depth_mode": "mesh"}, ValueError, "depth=True"),
        ({"depth": True, "depth_mode": "far"}, ValueError, "depth_mode"),
        ({"depth": True, "surface_opacity": 0.0}, ValueError, "surface_opacity"),
        ({"lod": "half"}, ValueError, "lod"),
        ({"lod": 1}, TypeError, "lod"),
    ]:
        with pytest.raises(error, match=match):
            scene.render(**kwargs)
    with pytest.raises(ValueError, match="outside"):
        scene.pick((500, 10), size=(100, 100))
    with pytest.raises(splatscene.SplatsceneError, match="nothing|no mesh|not in"):
        scene.contact("femur")


def test_bad_scene_and_mesh_arguments_are_refused():
    volume = splatscene.Volume.from_array(GOOD)
    for kwargs, error, match in [
        ({"volumes": [volume], "transfer": "ramp"}, ValueError, "window"),
        ({"volumes": [volume], "window": (5, 1)}, ValueError, "window"),
        ({"volumes": [volume], "transfer": "ct-glass"}, splatscene.SplatsceneError, "ct-glass"),
        ({"meshes": [], "transfer": "ct-bone"}, ValueError, "no"),
        ({"volumes": [volume], "crop_box": ((0, 0, 0), (1, 1))}, ValueError, "crop_box"),
        ({"volumes": [volume], "clip_meshes": True}, ValueError, "crop_box"),
        ({"volumes": [volume], "background": (0, 0, 0), "transparent": True}, ValueError, "background"),
        ({"volumes": [42]}, TypeError, "Volume"),
        ({"volumes": volume}, TypeError, "list"),
        ({"volumes": [volume], "view": "upwards"}, splatscene.SplatsceneError, "upwards"),
    ]:
        with pytest.raises(error, match=match):
            splatscene.Scene(**kwargs)
    vertices = np.zeros((3, 3))
    for args, kwargs, error, match in [
        ((np.zeros((3, 2)), [[0, 1, 2]]), {}, ValueError, "vertices"),
        ((vertices, [[0, 1, 3]]), {}, ValueError, "vertex 3"),
        ((vertices, [[0, 1, -1]]), {}, ValueError, "vertex -1"),
        ((vertices, [[0.0, 1.0, 2.0]]), {}, TypeError, "whole numbers"),
        ((np.full((3, 3), np.nan), [[0, 1, 2]]), {}, ValueError, "finite"),
        ((vertices, [[0, 1, 2]]), {"color": (2, 0, 0)}, ValueError, "color"),
        ((vertices, [[0, 1, 2]]), {"opacity": 0.0}, ValueError, "opacity"),
        ((vertices, [[0, 1, 2]]), {"scale": (1, 0, 1)}, ValueError, "scale"),
        ((vertices, [[0, 1, 2]]), {"matrix": np.eye(4), "translate": (1, 2, 3)}, ValueError, "matrix"),
        ((vertices, [[0, 1, 2]]), {"matrix": np.zeros((4, 4))}, ValueError, "matrix"),
    ]:
        with pytest.raises(error, match=match):
            splatscene.Mesh.from_arrays(*args, **kwargs)
    for args, kwargs, error, match in [
        (((4, 4, 4), (1, 2)), {}, ValueError, "eye"),
        (((4, 4, 4), (9, 9, 9), "sideways"), {}, ValueError, "ordering"),
        (((4, 4, 4), (9, 9, 9), "btf"), {"bucket_width": 0.5}, ValueError, "bucket"),
        (((4, 4, 4), (9, 9, 9)), {"spacing": (1, -1, 1)}, ValueError, "spacing"),
        (((1600, 1600, 1600), (9, 9, 9)), {}, splatscene.SplatsceneError, "memory"),
    ]:
        with pytest.raises(error, match=match):
            splatscene.order(*args, **kwargs)
    with pytest.raises(TypeError):
        splatscene.error("not a volume", (1, 2, 3))


def test_a_picture_shows_in_notebooks_as_png():
    scene = splatscene.Scene.from_file(REPO / "examples" / "scenes" / "shoulder.toml")
    image = scene.render(size=(64, 48))
    png = image._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    # Width and height in the IHDR chunk.
    assert int.from_bytes(png[16:20], "big") == 64 and int.from_bytes(png[20:24], "big") == 48
    from conftest import read_png
    import io
    from PIL import Image as PilImage

    assert np.array_equal(np.array(PilImage.open(io.BytesIO(png)).convert("RGBA")), np.asarray(image))


def test_rendering_lets_other_python_threads_run():
    scene = splatscene.Scene.from_file(REPO / "examples" / "scenes" / "shoulder.toml")
    scene.render(size=(32, 24), lod=False)  # classify first: the timed draw below is all renderer
    span = []

    def draw():
        start = time.perf_counter()
        scene.render(size=(1000, 750), lod=False)
        span.extend([start, time.perf_counter()])

    ticks = []
    worker = threading.Thread(target=draw)
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    start, end = span
    during = [t for t in ticks if start < t < end]
    # Python kept running while the picture was drawn; with the GIL held through the draw the
    # loop above could not tick inside it at all.
    assert end - start > 0.02, end - start
    assert len(during) > 0.25 * (end - start) / 0.0011, (len(during), end - start)
