"""Every function against the command line on the same inputs: a picture from a scene file
equal to ``splatscene render`` of that file, pixel for pixel; the depth to the depth image's
precision; ``load_volume`` equal to ``splatscene info``; ``order`` to ``splatscene order``;
``pick`` and ``contact`` to their commands."""

import math

import numpy as np
import pytest

import splatscene
from conftest import REPO, cli, cli_json, cli_render, data_file, read_png

SHOULDER = REPO / "examples" / "scenes" / "shoulder.toml"


def test_a_scene_file_renders_as_the_command_line_renders_it(tmp_path):
    scene = splatscene.Scene.from_file(SHOULDER)
    mine = scene.render(size=(240, 180))
    theirs = cli_render(SHOULDER, tmp_path / "a.png", "--size", "240x180")
    assert isinstance(mine, splatscene.Image) and isinstance(mine, np.ndarray)
    assert mine.shape == (180, 240, 4) and mine.dtype == np.uint8
    assert np.array_equal(mine, theirs)
    # Something is drawn: the phantom and the stem cover a good part of the picture.
    assert (np.abs(mine[..., :3].astype(int) - mine[0, 0, :3]).sum(axis=2) > 30).mean() > 0.1


def test_named_views_orbits_annotations_and_orderings_match_the_command_line(tmp_path):
    scene = splatscene.Scene.from_file(SHOULDER)
    cases = [
        (dict(view="left", annotate=True, caption="{view}"), ["--view", "left", "--annotate", "--caption", "{view}"]),
        (dict(orbit=(30, 10), ordering="btf", caption="stem {view} {size} {ordering}"),
         ["--orbit", "30,10", "--ordering", "btf", "--caption", "stem {view} {size} {ordering}"]),
        (dict(eye=(300, 40, 60), target=(47, 33, 55), annotate="marker,scale"), ["--eye", "300,40,60", "--target", "47,33,55", "--annotate", "marker,scale"]),
        (dict(view="superior", orthographic=160.0, lod=False), ["--view", "superior", "--orthographic", "160", "--lod", "off"]),
        (dict(view="anterior", lod="on"), ["--view", "anterior", "--lod", "on"]),
        (dict(view="anterior", lod="volume"), ["--view", "anterior", "--lod", "volume"]),
    ]
    for i, (options, flags) in enumerate(cases):
        mine = scene.render(size=(200, 160), **options)
        theirs = cli_render(SHOULDER, tmp_path / f"{i}.png", "--size", "200x160", *flags)
        assert np.array_equal(mine, theirs), (options, np.abs(mine.astype(int) - theirs).max())


def test_the_scene_files_own_size_is_the_default(tmp_path):
    scene = splatscene.Scene.from_file(REPO / "examples" / "scenes" / "cthead-fig1.toml")
    assert scene.size is not None
    mine = scene.render()
    theirs = cli_render(REPO / "examples" / "scenes" / "cthead-fig1.toml", tmp_path / "c.png")
    assert mine.shape[:2] == (scene.size[1], scene.size[0])
    assert np.array_equal(mine, theirs)


def test_a_real_ct_with_a_mesh_renders_as_the_command_line(tmp_path):
    scene_file = REPO / "examples" / "scenes" / "overlay-lidc2.toml"
    data_file("volumes/lidc2/lidc2_256x256x133_uint8.raw")
    mine = splatscene.Scene.from_file(scene_file).render(size=(256, 192))
    theirs = cli_render(scene_file, tmp_path / "o.png", "--size", "256x192")
    assert np.array_equal(mine, theirs)


def test_depth_is_the_command_lines_depth_image_in_millimetres(tmp_path):
    scene = splatscene.Scene.from_file(SHOULDER)
    for mode in ("mesh", "surface"):
        image, depth = scene.render(size=(160, 120), depth=True, depth_mode=mode)
        out, depth_png = tmp_path / f"{mode}.png", tmp_path / f"{mode}-depth.png"
        cli("render", SHOULDER, "--out", out, "--size", "160x120", "--depth", depth_png, "--depth-mode", mode)
        assert np.array_equal(image, read_png(out))
        grey = read_png(depth_png)
        calibration = __import__("json").loads((tmp_path / f"{mode}-depth.json").read_text())
        near, far = calibration["near_mm"], calibration["far_mm"]
        assert depth.shape == (120, 160) and depth.dtype == np.float32
        hit = grey != 65535
        assert np.array_equal(hit, ~np.isnan(depth)), mode
        assert hit.mean() > 0.02, mode
        decoded = near + (far - near) * grey[hit] / 65534.0
        step = (far - near) / 65534.0
        assert np.abs(decoded - depth[hit]).max() <= step / 2 + 1e-3 * far, mode
    # The surface mode sees the bone in front of the stem as well: more pixels hit.
    _, mesh = scene.render(size=(160, 120), depth=True, depth_mode="mesh")
    _, surface = scene.render(size=(160, 120), depth=True, depth_mode="surface")
    assert (~np.isnan(surface)).sum() > (~np.isnan(mesh)).sum()


VOLUMES = [
    ("volumes/totalseg_ct/aorta_ct_cropped.nii.gz", {}, []),
    ("volumes/totalseg_ct/example_ct_dicom", {}, []),
    ("volumes/vtk_headsq/quarter.nhdr", {}, []),
    ("volumes/datraw_small/Bucky_32x32x32_uint8.dat", {}, []),
    ("reader_tests/nibabel_test_data/example4d.nii.gz", {"frame": 1}, ["--frame", "1"]),
    ("reader_tests/nibabel_test_data/anatomical.nii", {"nifti_transform": "qform"}, ["--nifti-transform", "qform"]),
    ("reader_tests/pydicom_test_files/CT_small.dcm", {}, []),
]


@pytest.mark.parametrize("relative,options,flags", VOLUMES, ids=[v[0].split("/")[-1] for v in VOLUMES])
def test_load_volume_describes_what_info_describes(relative, options, flags):
    path = data_file(relative)
    volume = splatscene.load_volume(path, **options)
    info = cli_json("info", path, *flags)
    mine = volume.info()
    for key in ("format", "size", "scalar_type", "min", "max", "file"):
        assert mine[key] == info[key], key
    for key in ("spacing", "origin", "direction", "mean"):
        assert np.allclose(mine[key], info[key], rtol=1e-12, atol=1e-9), key
    nx, ny, nz = info["size"]
    assert volume.array.shape == (nz, ny, nx)
    assert volume.dims == (nx, ny, nz)
    assert np.allclose(volume.spacing, info["spacing"]) and np.allclose(volume.origin, info["origin"])
    assert np.allclose(volume.direction, info["direction"])
    assert math.isclose(float(volume.array.min()), info["min"]) and math.isclose(float(volume.array.max()), info["max"])
    assert volume.frame == options.get("frame", 0)
    # The affine puts voxel (i, j, k) where origin + direction * spacing * (i, j, k) is.
    ijk = np.array([3.0, 2.0, 1.0])
    expected = np.asarray(volume.origin) + volume.direction @ (np.asarray(volume.spacing) * ijk)
    assert np.allclose(volume.affine @ np.append(ijk, 1.0), np.append(expected, 1.0))


def test_a_raw_volume_loads_with_the_command_lines_options(tmp_path):
    values = (np.arange(6 * 5 * 4) % 251).astype(np.uint16).reshape(4, 5, 6)
    raw = tmp_path / "block.raw"
    raw.write_bytes(values.astype(">u2").tobytes())
    volume = splatscene.load_volume(raw, dims=(6, 5, 4), scalar="u16be", spacing=(0.5, 0.6, 2), origin=(1, 2, 3), orientation="LPS")
    assert volume.array.dtype == np.uint16 and np.array_equal(volume.array, values)
    assert volume.spacing == (0.5, 0.6, 2.0) and volume.origin == (1.0, 2.0, 3.0)
    assert np.allclose(volume.direction, np.diag([-1.0, -1.0, 1.0]))
    assert volume.format == "raw"
    scene = splatscene.Scene([volume], transfer="ramp", window=(50, 250))
    mine = scene.render(size=(96, 80))
    theirs = cli_render(raw, tmp_path / "r.png", "--dims", "6,5,4", "--scalar", "u16be", "--spacing", "0.5,0.6,2",
                        "--origin", "1,2,3", "--orientation", "LPS", "--window", "50,250", "--size", "96x80")
    assert np.array_equal(mine, theirs)


@pytest.mark.parametrize("ordering", ["btf", "wbtf", "pbtf", "ip-pbtf", "ip-pbtf-explicit", "exact", "bucketed", "pyramid", "rows"])
def test_order_is_the_command_lines_order(tmp_path, ordering):
    out = tmp_path / "order.bin"
    cli("order", "--dims", "7,5,6", "--spacing", "0.7,0.7,2.5", "--eye", "3.2,-9,4.4", "--ordering", ordering, "--out", out)
    theirs = np.frombuffer(out.read_bytes(), dtype="<u4")
    mine = splatscene.order((7, 5, 6), (3.2, -9, 4.4), ordering, spacing=(0.7, 0.7, 2.5))
    assert mine.dtype == np.uint32 and np.array_equal(mine, theirs)
    assert sorted(mine.tolist()) == list(range(7 * 5 * 6))


def test_order_with_a_target_and_the_cull_is_the_command_lines(tmp_path):
    out = tmp_path / "order.bin"
    cli("order", "--dims", "8,8,8", "--eye", "3,4,5", "--target", "7,7,0", "--ordering", "ip-pbtf", "--cull-behind-eye", "--out", out)
    theirs = np.frombuffer(out.read_bytes(), dtype="<u4")
    mine = splatscene.order((8, 8, 8), (3, 4, 5), "ip-pbtf", target=(7, 7, 0), cull_behind_eye=True)
    assert np.array_equal(mine, theirs) and len(mine) < 512


def test_pick_is_the_command_lines_pick():
    scene = splatscene.Scene.from_file(SHOULDER)
    for pixel, flags, options in [((120, 90), [], {}), ((100, 80), ["--meshes-only"], {"meshes_only": True}), ((5, 5), [], {})]:
        theirs = cli_json("pick", SHOULDER, "--size", "240x180", "--pixel", f"{pixel[0]},{pixel[1]}", *flags)
        mine = scene.pick(pixel, size=(240, 180), **options)
        assert mine == theirs


def test_contact_is_the_command_lines_contact():
    scene = splatscene.Scene.from_file(SHOULDER)
    assert scene.contact() == cli_json("contact", SHOULDER)
    assert scene.contact("prosthesis", classes=[0, 400]) == cli_json("contact", SHOULDER, "--mesh", "prosthesis", "--classes", "0,400")


def test_error_measures_each_ordering_against_the_exact_order():
    volume = splatscene.load_volume(data_file("volumes/datraw_small/Bucky_32x32x32_uint8.dat"))
    rows = splatscene.error(volume, (70, -40, 50), orderings=["btf", "ip-pbtf", "exact"], size=(64, 64), transfer="ramp", window=(60, 255))
    assert [r["ordering"] for r in rows] == ["btf", "ip-pbtf-implicit", "exact"]
    exact = rows[2]
    assert exact["rmse"] == 0 and exact["max_difference"] == 0 and exact["inversions"] == 0
    for r in rows:
        assert r["case"] in ("corner-on", "edge-on", "face-on", "volume-on")
        assert 0 <= r["rmse"] <= r["max_difference"] <= 1 and r["order_ms"] >= 0
    # Back to front by whole slabs (BTF) is no better than IP-PBTF on such a view.
    assert rows[1]["rmse"] <= rows[0]["rmse"] + 1e-9


def test_the_renderer_is_kept_between_pictures_so_volumes_are_classified_once():
    scene = splatscene.Scene.from_file(SHOULDER)
    assert scene.report is None
    scene.render(size=(160, 120))
    first = scene.report
    assert first["classified"] == 1 and first["splats"] > 1000 and first["meshes"] >= 1
    scene.render(size=(160, 120), orbit=(40, 0))
    assert scene.report["classified"] == 0
    # A scene of its own has a renderer of its own.
    other = splatscene.Scene.from_file(SHOULDER)
    other.render(size=(160, 120))
    assert other.report["classified"] == 1


def test_error_takes_one_ordering_by_name():
    volume = splatscene.load_volume(data_file("volumes/datraw_small/Bucky_32x32x32_uint8.dat"))
    rows = splatscene.error(volume, (70, -40, 50), orderings="pbtf", size=(48, 48))
    assert [r["ordering"] for r in rows] == ["pbtf"]
    with pytest.raises(ValueError, match="empty"):
        splatscene.error(volume, (70, -40, 50), orderings=[])
