"""Images held by SimpleITK and nibabel render to the picture of the files they were read
from, and arrays and meshes made in Python to the picture of the same things in files."""

import nibabel as nib
import numpy as np
import pytest
import SimpleITK as sitk

import splatscene
from conftest import cli_render, data_file


NIFTI = "volumes/totalseg_ct/aorta_ct_cropped.nii.gz"


def close_pictures(a, b):
    """Equal but for the last bit of the geometry's floating point: the readers compute the
    same placement in different orders of operations."""
    diff = np.abs(a.astype(int) - b.astype(int))
    assert diff.max() <= 2 and (diff > 0).mean() < 0.002, (diff.max(), (diff > 0).mean())


@pytest.mark.parametrize("relative", [NIFTI, "volumes/totalseg_ct/example_ct_dicom", "reader_tests/pydicom_test_files/CT_small.dcm"])
def test_a_simpleitk_image_renders_as_its_file(tmp_path, relative):
    path = data_file(relative)
    if path.is_dir():
        reader = sitk.ImageSeriesReader()
        reader.SetFileNames(reader.GetGDCMSeriesFileNames(str(path)))
        image = reader.Execute()
    else:
        image = sitk.ReadImage(str(path))
    from_sitk = splatscene.Volume.from_sitk(image)
    from_file = splatscene.load_volume(path)
    assert from_sitk.array.shape == from_file.array.shape
    assert np.array_equal(from_sitk.array.astype(np.float64), from_file.array.astype(np.float64))
    assert np.allclose(from_sitk.origin, from_file.origin, atol=1e-4)
    assert np.allclose(from_sitk.direction, from_file.direction, atol=1e-6)
    assert np.allclose(from_sitk.spacing, from_file.spacing, rtol=1e-6)
    mine = splatscene.Scene([from_sitk]).render(size=(160, 128))
    theirs = cli_render(path, tmp_path / "f.png", "--size", "160x128")
    close_pictures(mine, theirs)


@pytest.mark.parametrize("relative", [NIFTI, "reader_tests/nibabel_test_data/anatomical.nii", "reader_tests/nibabel_test_data/example_nifti2.nii.gz"])
def test_a_nibabel_image_renders_as_its_file(tmp_path, relative):
    path = data_file(relative)
    img = nib.load(str(path))
    from_nib = splatscene.Volume.from_nibabel(img)
    from_file = splatscene.load_volume(path)
    assert np.array_equal(from_nib.array.astype(np.float64), from_file.array.astype(np.float64))
    assert np.allclose(from_nib.affine, from_file.affine, atol=1e-4)
    mine = splatscene.Scene([from_nib], transfer="ct-bone").render(size=(160, 128), view="left")
    theirs = cli_render(path, tmp_path / "f.png", "--size", "160x128", "--view", "left", "--preset", "ct-bone")
    close_pictures(mine, theirs)


def test_a_frame_of_a_4d_nibabel_image_is_the_files_frame():
    path = data_file("reader_tests/nibabel_test_data/example4d.nii.gz")
    from_nib = splatscene.Volume.from_nibabel(nib.load(str(path)), frame=1)
    from_file = splatscene.load_volume(path, frame=1)
    assert np.array_equal(from_nib.array.astype(np.float64), from_file.array.astype(np.float64))
    with pytest.raises(ValueError, match="frame 9"):
        splatscene.Volume.from_nibabel(nib.load(str(path)), frame=9)


def test_a_sitk_image_with_a_placed_mesh_renders_as_the_command_line(tmp_path):
    """The notebook's few lines: a CT read with SimpleITK, a mesh placed, the picture of the
    command line given the same file and mesh."""
    path = data_file(NIFTI)
    ct = splatscene.Volume.from_sitk(sitk.ReadImage(str(path)))
    humerus = data_file("meshes/myosim_shoulder/humerus.stl")
    bone = splatscene.Mesh.from_file(humerus, units="m", translate=(-40, 120, 430), rotate_degrees=(0, 20, 0))
    picture = splatscene.Scene([ct], [bone], transfer="ct-bone").render(size=(200, 160), annotate=True)
    theirs = cli_render(path, tmp_path / "s.png", "--size", "200x160", "--preset", "ct-bone", "--annotate",
                        "--mesh", humerus, "--mesh-units", "m",
                        "--mesh-transform", "{ translate = [-40, 120, 430], rotate_degrees = [0, 20, 0] }")
    close_pictures(picture, theirs)


def test_an_array_in_either_axis_order_is_the_same_volume(tmp_path):
    rng = np.random.default_rng(7)
    zyx = rng.integers(0, 255, size=(12, 10, 8), dtype=np.uint8)
    a = splatscene.Volume.from_array(zyx, spacing=(0.8, 0.9, 2.0), origin=(-3, 4, 5))
    b = splatscene.Volume.from_array(np.asfortranarray(zyx.transpose(2, 1, 0)), spacing=(0.8, 0.9, 2.0), origin=(-3, 4, 5), axes="xyz")
    assert a.dims == b.dims == (8, 10, 12)
    assert np.array_equal(a.array, b.array) and np.array_equal(a.array, zyx)
    # The same values written as a raw file and given to the command line.
    raw = tmp_path / "v.raw"
    raw.write_bytes(zyx.tobytes())
    mine = splatscene.Scene([a], transfer="ramp", window=(100, 250)).render(size=(120, 96))
    theirs = cli_render(raw, tmp_path / "v.png", "--dims", "8,10,12", "--scalar", "u8", "--spacing", "0.8,0.9,2",
                        "--origin", "-3,4,5", "--window", "100,250", "--size", "120x96")
    assert np.array_equal(mine, theirs)


def test_wider_types_become_float32_with_their_values():
    values = np.arange(2 * 3 * 4).reshape(2, 3, 4)
    for dtype in (np.int32, np.uint32, np.int64, np.float64):
        v = splatscene.Volume.from_array(values.astype(dtype))
        assert v.array.dtype == np.float32 and np.array_equal(v.array, values)
    for dtype in (np.uint8, np.int8, np.uint16, np.int16, np.float32):
        assert splatscene.Volume.from_array(values.astype(dtype)).array.dtype == dtype


def test_the_array_is_a_read_only_view_of_the_volume():
    v = splatscene.load_volume(data_file(NIFTI))
    a = v.array
    assert not a.flags.writeable
    assert a.base is not None
    with pytest.raises(ValueError):
        a[0, 0, 0] = 1
    del v
    assert int(a[0, 0, 0]) == int(a[0, 0, 0])  # the memory outlives the Volume object


def test_a_mesh_from_arrays_draws_as_the_same_mesh_from_a_file(tmp_path):
    vertices = np.array([[0, 0, 0], [30, 0, 0], [30, 30, 0], [0, 30, 0],
                         [0, 0, 30], [30, 0, 30], [30, 30, 30], [0, 30, 30]], dtype=float)
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                      [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    obj = tmp_path / "cube.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in vertices) + "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in faces))
    from_arrays = splatscene.Mesh.from_arrays(vertices, faces, name="cube.obj", color=(0.9, 0.5, 0.2))
    from_file = splatscene.Mesh.from_file(obj, color=(0.9, 0.5, 0.2))
    assert np.array_equal(from_arrays.faces, faces) and np.allclose(from_arrays.vertices, vertices)
    a = splatscene.Scene(meshes=[from_arrays.placed(rotate_degrees=(10, 20, 30))]).render(size=(100, 80))
    b = splatscene.Scene(meshes=[from_file.placed(rotate_degrees=(10, 20, 30))]).render(size=(100, 80))
    assert np.array_equal(a, b)
    assert (np.abs(a[..., :3].astype(int) - a[0, 0, :3]).sum(axis=2) > 30).mean() > 0.05


def test_simpleitks_flat_direction_is_taken_row_by_row():
    image = sitk.Image(6, 5, 4, sitk.sitkInt16)
    turned = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    image.SetDirection(turned)
    v = splatscene.Volume.from_array(sitk.GetArrayFromImage(image), direction=image.GetDirection())
    assert np.allclose(v.direction, np.array(turned).reshape(3, 3))
    ras = splatscene.Volume.from_sitk(image)
    assert np.allclose(ras.direction, np.diag([-1, -1, 1]) @ np.array(turned).reshape(3, 3))


def test_contact_of_a_mesh_built_in_python_is_that_of_its_file(tmp_path):
    ct = splatscene.load_volume(data_file(NIFTI))
    humerus = data_file("meshes/myosim_shoulder/humerus.stl")
    bone = splatscene.Mesh.from_file(humerus, units="m", translate=(-20, 160, 660))
    scene = splatscene.Scene([ct], [bone])
    by_object = scene.contact(bone)
    assert by_object == scene.contact("humerus.stl") == scene.contact()
    from conftest import cli_json
    theirs = cli_json("contact", data_file(NIFTI), "--mesh", humerus, "--mesh-units", "m",
                      "--mesh-transform", "{ translate = [-20, 160, 660] }")
    assert by_object == theirs
    assert by_object["area_mm2"] > 1000
