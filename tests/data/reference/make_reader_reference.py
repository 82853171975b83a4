"""Independent reference figures for the third-party reader test files.

Reads every DICOM file in <data>/reader_tests/pydicom_test_files/ (files from pydicom's test
suite; LICENSE and README.txt are skipped) and every .nii / .nii.gz file in
<data>/reader_tests/nibabel_test_data/ (files from nibabel's test suite), and prints one JSON
document with, per file, the geometry and value statistics that splatscene's loaders must
reproduce. No voxel arrays are stored.

Conventions (the project's):
  * a volume has dims [nx, ny, nz], x fastest in memory; for DICOM nx = Columns,
    ny = Rows, nz = number of frames (1 for a single-frame image);
  * voxel index (i, j, k) sits at world point origin + D @ (spacing * (i, j, k)), where the
    columns of D are the unit axis directions; `direction` lists the three ROWS of D;
  * the world frame is RAS+. DICOM / ITK points are LPS+: a point is converted by negating
    x and y, an ITK direction matrix by negating its first two rows. NIfTI is already RAS+;
  * spacing from an affine = the norms of its first three columns, direction = those columns
    divided by the norms (a negative determinant is kept, never flipped);
  * `index_point` gives the world point of index (1, 2, 0) and, when nz > 1, of (1, 2, nz-1);
  * values are after the modality rescale: DICOM RescaleSlope / RescaleIntercept (pydicom's
    apply_rescale), RT Dose also DoseGridScaling, NIfTI scl_slope / scl_inter (nibabel's
    get_fdata()). min / max / mean / sum are float64 over all voxels (sum with math.fsum;
    with NaNs present they read "nan" and `finite` holds the figures over finite voxels);
    `at_0_0_0`, `at_1_2_0`, `at_last`, `at_mid` are the values at index (0,0,0), (1,2,0),
    (nx-1, ny-1, nz-1) and (nx//2, ny//2, nz//2).

Which library gives what:
  * DICOM geometry: SimpleITK (sitk.ReadImage on the single file; ITK's GDCM reader),
    cross-checked against a computation by hand from the pydicom tags (`geometry_tags`):
    ImagePositionPatient, ImageOrientationPatient (first three = row direction = our x axis,
    last three = column direction = our y axis), PixelSpacing ([row spacing, column spacing],
    so sx = PixelSpacing[1], sy = PixelSpacing[0]); multi-frame frame positions from
    GridFrameOffsetVector (RT Dose) or the Per-frame / Shared Functional Groups. Where
    SimpleITK cannot read a file, the by-hand geometry is the reference (`reader` says so).
  * DICOM values: pydicom's pixel_array (decoded by whatever pydicom plugin is available,
    pylibjpeg / pyjpegls for compressed syntaxes) and pydicom.pixels.apply_rescale.
    SimpleITK's values are recorded beside them (`values_simpleitk`) with the largest
    difference. Where pydicom cannot decode the pixel data but SimpleITK can, SimpleITK's
    values are the reference (`values_reader` says so).
  * NIfTI geometry and values: nibabel. The sform (get_sform, sform_code) and qform
    (get_qform, qform_code) are recorded separately, with which one nibabel's img.affine
    uses; SimpleITK's geometry (converted to RAS) is recorded beside them with which of the
    two it matches. The top-level geometry is nibabel's img.affine.

Produced with Python 3.11.7, numpy 2.4.6, pydicom 3.0.2, SimpleITK 2.5.7, nibabel 5.4.2,
pylibjpeg 2.1.0, pylibjpeg-libjpeg 2.5.0, pylibjpeg-openjpeg 2.6.0, pyjpegls 1.5.1
(pip install numpy pydicom SimpleITK nibabel pylibjpeg pylibjpeg-libjpeg
pylibjpeg-openjpeg pyjpegls). The versions actually used are written into the JSON.

Run, where /path/to/shared/data holds reader_tests/:
    python3 make_reader_reference.py /path/to/shared/data > reader_tests.json
"""
import hashlib
import io
import json
import math
import os
import platform
import re
import sys
import tempfile
from contextlib import contextmanager
from importlib import metadata

import nibabel as nib
import numpy as np
import pydicom
import pydicom.pixels
import SimpleITK as sitk

GEOM_TOL = 1e-4  # DS strings carry ~6-16 significant digits; this is generous but tight
VALUE_TOL = 1e-6


# ----------------------------------------------------------------------------------------
# small helpers


def pkg_version(name):
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def clean(x, nd=9):
    """Round geometry numbers to 1e-9 and turn -0.0 into 0.0, recursively."""
    if isinstance(x, (list, tuple)):
        return [clean(v, nd) for v in x]
    if isinstance(x, np.ndarray):
        return clean(x.tolist(), nd)
    if isinstance(x, (float, np.floating)):
        v = round(float(x), nd)
        return 0.0 if v == 0.0 else v
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


def num(x):
    """A JSON-safe scalar (float64 or int), -0.0 -> 0.0, NaN/inf as strings."""
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    v = float(x)
    if math.isnan(v) or math.isinf(v):
        return str(v)
    return 0.0 if v == 0.0 else v


def sha256(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def short_error(e):
    s = f"{type(e).__name__}: {e}".strip()
    # no machine-specific paths: keep only file names, drop ITK source locations
    s = re.sub(r"/[^\s\"']*/([^/\s\"']+)", r"\1", s)
    lines = [ln.strip() for ln in s.splitlines() if ln.strip()]
    # SimpleITK errors are multi-line; keep the meaningful last line(s)
    if len(lines) > 2:
        lines = [lines[0].split(":")[0] + ":"] + lines[-1:]
    return " ".join(lines)[:400]


@contextmanager
def capture_fd2():
    """Capture what C/C++ code (GDCM, ITK) writes to file descriptor 2."""
    sys.stderr.flush()
    saved = os.dup(2)
    tmp = tempfile.TemporaryFile(mode="w+b")
    os.dup2(tmp.fileno(), 2)
    box = {"text": ""}
    try:
        yield box
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
        tmp.seek(0)
        box["text"] = tmp.read().decode("utf-8", "replace")
        tmp.close()


def stderr_lines(text):
    out = []
    for ln in text.splitlines():
        ln = ln.strip()
        if ln and ln not in out:
            out.append(ln)
    return out[:8]


def geometry_dict(size, spacing, origin, D):
    """Geometry record in the project convention (all inputs already RAS)."""
    size = [int(s) for s in size]
    spacing = np.asarray(spacing, dtype=float)
    origin = np.asarray(origin, dtype=float)
    D = np.asarray(D, dtype=float)

    def world(idx):
        return origin + D @ (spacing * np.asarray(idx, dtype=float))

    pts = {"1,2,0": clean(world((1, 2, 0)))}
    if size[2] > 1:
        pts[f"1,2,{size[2] - 1}"] = clean(world((1, 2, size[2] - 1)))
    return {
        "size": size,
        "spacing": clean(spacing),
        "origin": clean(origin),
        "direction": clean(D),  # rows of D
        "index_point": pts,
    }


def compare_geometry(a, b, tol=GEOM_TOL):
    """List the fields where two geometry dicts differ by more than tol."""
    diffs = []
    if a["size"] != b["size"]:
        diffs.append(f"size {a['size']} vs {b['size']}")
    for key in ("spacing", "origin", "direction"):
        x = np.asarray(a[key], dtype=float)
        y = np.asarray(b[key], dtype=float)
        if x.shape != y.shape or np.max(np.abs(x - y)) > tol:
            diffs.append(f"{key} {a[key]} vs {b[key]}")
    return diffs


def stats(arr):
    """min/max/mean/sum over all voxels; with NaNs these are "nan" and `finite` has the
    figures over the finite voxels."""
    a = np.asarray(arr, dtype=np.float64)
    flat = a.ravel()

    def figures(v):
        total = math.fsum(v.tolist())
        return {"min": num(v.min()), "max": num(v.max()), "mean": num(total / v.size),
                "sum": num(total), "count": int(v.size)}

    finite = np.isfinite(flat)
    if finite.all():
        return figures(flat)
    r = {"min": "nan", "max": "nan", "mean": "nan", "sum": "nan", "count": int(flat.size),
         "nan_count": int(np.count_nonzero(np.isnan(flat))),
         "inf_count": int(np.count_nonzero(np.isinf(flat)))}
    if finite.any():
        r["finite"] = figures(flat[finite])
    return r


def max_abs_diff(a, b):
    """Largest |a - b| where both are finite; NaN positions must match (else inf)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    na, nb = np.isnan(a), np.isnan(b)
    if not np.array_equal(na, nb):
        return float("inf")
    m = ~na
    return float(np.max(np.abs(a[m] - b[m]))) if m.any() else 0.0


def spot_values(vol_xyz):
    """vol_xyz is indexed [i, j, k] (x, y, z)."""
    nx, ny, nz = vol_xyz.shape
    r = {"at_0_0_0": num(vol_xyz[0, 0, 0])}
    if nx > 1 and ny > 2:
        r["at_1_2_0"] = num(vol_xyz[1, 2, 0])
    r["at_last"] = num(vol_xyz[nx - 1, ny - 1, nz - 1])
    r["at_mid"] = num(vol_xyz[nx // 2, ny // 2, nz // 2])
    return r


def lps_to_ras_point(p):
    p = np.asarray(p, dtype=float).copy()
    p[:2] *= -1
    return p


def lps_to_ras_matrix(D):
    D = np.asarray(D, dtype=float).copy()
    D[:2, :] *= -1
    return D


# ----------------------------------------------------------------------------------------
# SimpleITK


def sitk_read(path):
    """Returns (geometry dict in RAS (3-D part) + extras, array [z, y, x, ...] or None)."""
    rec = {}
    with capture_fd2() as err:
        try:
            img = sitk.ReadImage(path)
        except Exception as e:  # noqa: BLE001
            img = None
            rec["error"] = short_error(e)
    msgs = stderr_lines(err["text"])
    if msgs:
        rec["messages"] = msgs
    if img is None:
        return rec, None
    dim = img.GetDimension()
    size = list(img.GetSize())
    spacing = list(img.GetSpacing())
    origin = list(img.GetOrigin())
    Dn = np.array(img.GetDirection(), dtype=float).reshape(dim, dim)
    D3 = np.eye(3)
    n = min(dim, 3)
    D3[:n, :n] = Dn[:n, :n]
    size3 = (size + [1, 1, 1])[:3]
    spacing3 = (spacing + [1.0, 1.0, 1.0])[:3]
    origin3 = (origin + [0.0, 0.0, 0.0])[:3]
    g = geometry_dict(size3, spacing3, lps_to_ras_point(origin3), lps_to_ras_matrix(D3))
    rec.update(g)
    rec["dimension"] = dim
    if dim > 3:
        rec["size_nd"] = size
        rec["spacing_nd"] = clean(spacing)
        rec["origin_nd_lps"] = clean(origin)
    rec["pixel_type"] = img.GetPixelIDTypeAsString()
    rec["components_per_pixel"] = img.GetNumberOfComponentsPerPixel()
    arr = sitk.GetArrayFromImage(img)
    return rec, arr


# ----------------------------------------------------------------------------------------
# DICOM


def ds_get(ds, keyword, default=None):
    try:
        v = ds.get(keyword, default)
    except Exception:  # noqa: BLE001
        return default
    return default if v is None else v


def functional_groups_item(ds, seq_keyword, frame=0):
    """First item of seq_keyword from per-frame group `frame`, else from the shared group."""
    pf = ds_get(ds, "PerFrameFunctionalGroupsSequence")
    if pf is not None and len(pf) > frame:
        s = ds_get(pf[frame], seq_keyword)
        if s:
            return s[0], "PerFrameFunctionalGroupsSequence"
    sh = ds_get(ds, "SharedFunctionalGroupsSequence")
    if sh:
        s = ds_get(sh[0], seq_keyword)
        if s:
            return s[0], "SharedFunctionalGroupsSequence"
    return None, None


def dicom_geometry_by_hand(ds, nframes):
    """Geometry from the tags, in RAS. Returns (geometry dict with `source`, notes)."""
    notes = []
    src = {}
    cols = int(ds.Columns)
    rows = int(ds.Rows)

    # orientation
    iop = ds_get(ds, "ImageOrientationPatient")
    if iop is not None:
        src["orientation"] = "ImageOrientationPatient (top level)"
    else:
        item, where = functional_groups_item(ds, "PlaneOrientationSequence")
        if item is not None and ds_get(item, "ImageOrientationPatient") is not None:
            iop = item.ImageOrientationPatient
            src["orientation"] = f"PlaneOrientationSequence in {where}"
    if iop is None:
        iop = [1, 0, 0, 0, 1, 0]
        src["orientation"] = "absent; identity assumed"
    iop = np.array([float(v) for v in iop])
    row_dir = iop[:3] / np.linalg.norm(iop[:3])
    col_dir = iop[3:] / np.linalg.norm(iop[3:])
    normal = np.cross(row_dir, col_dir)

    # pixel spacing
    ps = ds_get(ds, "PixelSpacing")
    sbs = ds_get(ds, "SpacingBetweenSlices")
    if ps is not None:
        src["pixel_spacing"] = "PixelSpacing (top level)"
    else:
        item, where = functional_groups_item(ds, "PixelMeasuresSequence")
        if item is not None and ds_get(item, "PixelSpacing") is not None:
            ps = item.PixelSpacing
            src["pixel_spacing"] = f"PixelMeasuresSequence in {where}"
            if sbs is None:
                sbs = ds_get(item, "SpacingBetweenSlices")
    if ps is None:
        ps = [1.0, 1.0]
        src["pixel_spacing"] = "absent; 1 assumed"
    sx, sy = float(ps[1]), float(ps[0])

    # frame positions (LPS)
    ipp = ds_get(ds, "ImagePositionPatient")
    positions = None
    gfov = ds_get(ds, "GridFrameOffsetVector")
    pf = ds_get(ds, "PerFrameFunctionalGroupsSequence")
    if ipp is not None:
        ipp = np.array([float(v) for v in ipp])
        src["position"] = "ImagePositionPatient (top level)"
        if nframes > 1 and gfov is not None:
            g = np.array([float(v) for v in gfov])[:nframes]
            if g[0] == 0.0:
                rel = g
                src["frames"] = "GridFrameOffsetVector, relative (first value 0), along row x column"
            else:
                rel = g - g[0]
                src["frames"] = ("GridFrameOffsetVector, absolute (first value != 0), taken "
                                 "relative to the first, along row x column")
            positions = ipp[None, :] + rel[:, None] * normal[None, :]
        else:
            positions = ipp[None, :]
    elif pf is not None:
        pos = []
        for f in range(min(nframes, len(pf))):
            s = ds_get(pf[f], "PlanePositionSequence")
            if s and ds_get(s[0], "ImagePositionPatient") is not None:
                pos.append([float(v) for v in s[0].ImagePositionPatient])
        if pos:
            positions = np.array(pos)
            src["position"] = "PlanePositionSequence in PerFrameFunctionalGroupsSequence"
            if len(pf) != nframes:
                notes.append(f"PerFrameFunctionalGroupsSequence has {len(pf)} items but the "
                             f"file has {nframes} frame(s) of pixel data (NumberOfFrames "
                             f"{ds_get(ds, 'NumberOfFrames', 'absent')}); the first "
                             f"{nframes} item(s) are used")
    if positions is None:
        positions = np.zeros((1, 3))
        src["position"] = "absent; origin 0 assumed"

    origin = positions[0]
    if nframes > 1 and len(positions) == nframes:
        step = (positions[-1] - positions[0]) / (nframes - 1)
        sz = float(np.linalg.norm(step))
        zdir = step / sz
        expected = positions[0][None, :] + np.arange(nframes)[:, None] * step[None, :]
        dev = float(np.max(np.abs(positions - expected)))
        src["z_spacing"] = "distance between first and last frame / (frames - 1)"
        if dev > GEOM_TOL:
            notes.append(f"frame positions are not evenly spaced (max deviation {dev:.3g} mm)")
        d = float(np.dot(zdir, normal))
        if abs(abs(d) - 1) > 1e-6:
            notes.append(f"frame axis is not along row x column (dot {d:.6f})")
        elif d < 0:
            notes.append("frames run against row x column (z axis = -normal)")
    else:
        zdir = normal
        if sbs is not None:
            sz = float(sbs)
            src["z_spacing"] = "SpacingBetweenSlices (single slice; affects no voxel position)"
        else:
            sz = 1.0
            src["z_spacing"] = "1 (single slice, no SpacingBetweenSlices; affects no voxel position)"
    D_lps = np.column_stack([row_dir, col_dir, zdir])
    g = geometry_dict([cols, rows, nframes], [sx, sy, sz], lps_to_ras_point(origin),
                      lps_to_ras_matrix(D_lps))
    g["source"] = src
    if len(positions) > 1:
        g["frame_positions_ras"] = {
            "first": clean(lps_to_ras_point(positions[0])),
            "second": clean(lps_to_ras_point(positions[1])),
            "last": clean(lps_to_ras_point(positions[-1])),
        }
    return g, notes


def dicom_rescale(ds):
    """(slope, intercept, where) as the DICOM tags give them."""
    slope = ds_get(ds, "RescaleSlope")
    inter = ds_get(ds, "RescaleIntercept")
    if slope is not None or inter is not None:
        return (float(slope) if slope is not None else 1.0,
                float(inter) if inter is not None else 0.0, "top level")
    item, where = functional_groups_item(ds, "PixelValueTransformationSequence")
    if item is not None:
        return (float(ds_get(item, "RescaleSlope", 1.0)),
                float(ds_get(item, "RescaleIntercept", 0.0)),
                f"PixelValueTransformationSequence in {where}")
    return None, None, None


LOSSY_TS = {
    "1.2.840.10008.1.2.4.50", "1.2.840.10008.1.2.4.51", "1.2.840.10008.1.2.4.81",
    "1.2.840.10008.1.2.4.91", "1.2.840.10008.1.2.4.201", "1.2.840.10008.1.2.4.203",
}


def read_dicom(path, data_dir):
    name = os.path.basename(path)
    raw = open(path, "rb").read()
    rec = {
        "format": "DICOM",
        "bytes": len(raw),
        "sha256": sha256(path),
        "has_preamble_and_DICM": len(raw) >= 132 and raw[128:132] == b"DICM",
    }
    notes = []
    errors = {}

    # --- pydicom: strict first, then force
    ds = None
    try:
        ds = pydicom.dcmread(path)
        rec["pydicom_read"] = "ok"
    except Exception as e:  # noqa: BLE001
        errors["pydicom_dcmread"] = short_error(e)
        try:
            with capture_fd2():
                ds = pydicom.dcmread(path, force=True)
            rec["pydicom_read"] = "only with force=True"
        except Exception as e2:  # noqa: BLE001
            errors["pydicom_dcmread_force"] = short_error(e2)
            rec["pydicom_read"] = "failed"

    fm = getattr(ds, "file_meta", None) if ds is not None else None
    ts = fm.get("TransferSyntaxUID") if fm is not None else None
    rec["has_file_meta"] = bool(fm is not None and len(fm) > 0)
    if ts is not None:
        rec["transfer_syntax"] = {"uid": str(ts), "name": ts.name}
    else:
        enc = None
        if ds is not None:
            try:
                impl, le = ds.original_encoding  # (is_implicit_VR, is_little_endian)
                enc = f"{'Implicit' if impl else 'Explicit'} VR {'Little' if le else 'Big'} Endian"
            except Exception:  # noqa: BLE001
                enc = None
        rec["transfer_syntax"] = {"uid": None, "name": None,
                                  "encoding_pydicom_detected": enc}

    if ds is not None and len(ds) <= 2 and "PixelData" not in ds and "SOPClassUID" not in ds:
        # pydicom "read" the file but found nothing meaningful
        keys = [str(k) for k in ds.keys()]
        errors["pydicom_dcmread_force"] = (
            f"force=True parses a meaningless dataset: {len(ds)} element(s) {keys}")
        rec["pydicom_read"] = "failed (force=True gives garbage)"
        ds_bad = True
    else:
        ds_bad = False

    if ds is not None and not ds_bad:
        sop = ds_get(ds, "SOPClassUID")
        rec["sop_class"] = f"{sop.name} ({sop})" if sop is not None else None
        rec["modality"] = ds_get(ds, "Modality")
        for kw in ("PhotometricInterpretation", "SamplesPerPixel", "BitsAllocated",
                   "BitsStored", "PixelRepresentation", "Rows", "Columns"):
            v = ds_get(ds, kw)
            rec[kw[0].lower() + "".join("_" + c.lower() if c.isupper() else c
                                        for c in kw[1:])] = (
                int(v) if isinstance(v, int) else (str(v) if v is not None else None))
        rec["number_of_frames_tag"] = (int(ds.NumberOfFrames)
                                       if ds_get(ds, "NumberOfFrames") is not None else None)
    if ts is not None:
        rec["lossy"] = str(ts) in LOSSY_TS
        if rec["lossy"]:
            notes.append(f"lossy transfer syntax ({ts.name})")
        try:
            if not ts.is_compressed:
                raise LookupError("native")
            dec = pydicom.pixels.get_decoder(ts)
            rec["pydicom_decoding_plugins"] = sorted(dec.available_plugins)
        except Exception:  # noqa: BLE001
            pass
    if not rec["has_preamble_and_DICM"]:
        notes.append("no 128-byte preamble / 'DICM' prefix and no file meta information")
    if ts is not None and str(ts) == "1.2.840.10008.1.2.1.99":
        notes.append("deflated dataset (zlib raw deflate after the file meta)")
    if ts is not None and str(ts) == "1.2.840.10008.1.2.2" or (
            ts is None and ds is not None and not ds_bad and not ds.original_encoding[1]):
        notes.append("big-endian dataset")

    has_pixels = ds is not None and not ds_bad and "PixelData" in ds
    if has_pixels and (ts is None or not ts.is_compressed):
        try:
            nf = int(ds_get(ds, "NumberOfFrames", 1) or 1)
            bits = int(ds.Rows) * int(ds.Columns) * int(ds.BitsAllocated) * nf * int(
                ds_get(ds, "SamplesPerPixel", 1))
            need = (bits + 7) // 8
            got = len(ds.PixelData)
            if got > need + (need % 2):
                notes.append(f"Pixel Data has {got} bytes, more than the {need} needed; "
                             "the extra bytes are padding")
        except Exception:  # noqa: BLE001
            pass
    if ds is not None and not ds_bad and 0xFFFCFFFC in ds:
        notes.append("ends with a (FFFC,FFFC) Data Set Trailing Padding element of "
                     f"{len(ds[0xFFFCFFFC].value)} bytes")
    if ds is not None and not ds_bad and not has_pixels:
        notes.append("no Pixel Data: not an image")

    # --- pydicom pixels
    stored = None
    if has_pixels:
        try:
            with capture_fd2():
                stored = ds.pixel_array
        except Exception as e:  # noqa: BLE001
            errors["pydicom_pixel_array"] = short_error(e)
            stored = None
        # each available decoding plugin separately, for compressed transfer syntaxes
        if ts is not None and ts.is_compressed and rec.get("pydicom_decoding_plugins"):
            per = {}
            for plugin in rec["pydicom_decoding_plugins"]:
                try:
                    with capture_fd2():
                        a = pydicom.pixels.pixel_array(path, decoding_plugin=plugin)
                    if stored is not None and a.shape == stored.shape and np.array_equal(
                            a, stored):
                        per[plugin] = "ok, identical to pixel_array"
                    elif stored is not None:
                        per[plugin] = (f"ok, differs from pixel_array: max |diff| "
                                       f"{max_abs_diff(a, stored):g}")
                    else:
                        per[plugin] = "ok"
                except Exception as e:  # noqa: BLE001
                    msg = short_error(e)
                    msg = msg.split("plugins: ", 1)[-1]
                    per[plugin] = "error: " + msg
            rec["pydicom_plugin_results"] = per

    nframes = None
    if ds is not None and not ds_bad and has_pixels:
        nf_tag = ds_get(ds, "NumberOfFrames")
        nframes = int(nf_tag) if nf_tag is not None else 1
        rec["frames"] = nframes
        if nframes > 1:
            notes.append(f"multi-frame: {nframes} frames")

    # --- SimpleITK
    srec, sarr = sitk_read(path)
    rec["geometry_simpleitk"] = srec
    if "error" in srec:
        errors["simpleitk"] = srec["error"]
    if srec.get("messages"):
        notes.append("GDCM/ITK printed while reading: " + " | ".join(srec["messages"]))

    # --- by-hand geometry
    gt = None
    if has_pixels:
        try:
            gt, gnotes = dicom_geometry_by_hand(ds, nframes)
            notes.extend(gnotes)
            rec["geometry_tags"] = gt
        except Exception as e:  # noqa: BLE001
            errors["geometry_tags"] = short_error(e)

    # --- reference geometry
    if "size" in srec:
        ref_geom = {k: srec[k] for k in ("size", "spacing", "origin", "direction", "index_point")}
        rec["reader"] = f"SimpleITK {sitk.Version_VersionString()} (sitk.ReadImage)"
        if gt is not None:
            diffs = compare_geometry(srec, gt)
            # for a single slice the z spacing is a convention; report it separately
            rec["geometry_agreement"] = (
                "SimpleITK and the by-hand tag computation agree (tolerance 1e-4)"
                if not diffs else "DISAGREE: " + "; ".join(diffs))
            if diffs:
                notes.append("SimpleITK and by-hand geometry disagree: " + "; ".join(diffs))
    elif gt is not None:
        ref_geom = {k: gt[k] for k in ("size", "spacing", "origin", "direction", "index_point")}
        rec["reader"] = (f"pydicom {pydicom.__version__} tags, by hand "
                         "(SimpleITK cannot read the file)")
    else:
        ref_geom = None
        rec["reader"] = None
    if ref_geom:
        rec.update(ref_geom)

    # --- values
    values = None
    sa = None
    if sarr is not None:
        sa = np.asarray(sarr, dtype=np.float64)
        if sa.ndim == 2:
            sa = sa[None, ...]
    if stored is not None:
        rec["stored_type"] = stored.dtype.newbyteorder("=").name
        # arrange as [frames, rows, cols]
        st = stored if stored.ndim == 3 else stored[None, ...]
        if stored.ndim not in (2, 3) or ds_get(ds, "SamplesPerPixel", 1) != 1:
            notes.append(f"pixel_array has shape {stored.shape}; not a scalar volume")
        slope, inter, where = dicom_rescale(ds)
        rescaled = pydicom.pixels.apply_rescale(st.copy(), ds)
        rescale_rec = {"slope": slope, "intercept": inter, "where": where,
                       "pydicom_apply_rescale_applied": where == "top level"}
        if where is not None and where != "top level":
            # pydicom's apply_rescale reads only the top-level tags
            rescaled = st.astype(np.float64) * slope + inter
            rescale_rec["note"] = ("applied by hand: pydicom's apply_rescale reads only "
                                   "top-level RescaleSlope/Intercept")
        dgs = ds_get(ds, "DoseGridScaling")
        values = np.asarray(rescaled, dtype=np.float64)
        if dgs is not None:
            rescale_rec["dose_grid_scaling"] = float(dgs)
            rescale_rec["dose_grid_scaling_applied_to_values"] = True
            rescale_rec["dose_units"] = ds_get(ds, "DoseUnits")
            rescale_rec["note_dose"] = ("values = stored x DoseGridScaling; stored_values are "
                                        "the raw integers (what SimpleITK returns)")
            values = values * float(dgs)
        rec["rescale"] = rescale_rec
        vol = np.transpose(values, (2, 1, 0))  # [frames, rows, cols] -> [i, j, k]
        v = stats(values)
        v.update(spot_values(vol))
        rec["values"] = v
        rec["values_reader"] = (f"pydicom {pydicom.__version__} pixel_array"
                                + " + pydicom.pixels.apply_rescale"
                                + (" x DoseGridScaling" if dgs is not None else ""))
        sv = stats(st)
        sv.update(spot_values(np.transpose(st, (2, 1, 0))))
        rec["stored_values"] = sv
        if int(ds_get(ds, "BitsAllocated", 0)) == 1:
            notes.append("BitsAllocated 1 (bit-packed binary segmentation): pydicom unpacks "
                         "to 0/1")
        if sa is not None:
            svs = stats(sa)
            svs.update(spot_values(np.transpose(sa, (2, 1, 0))))
            cmp = {}
            if sa.shape == values.shape:
                cmp["max_abs_diff_vs_values"] = num(max_abs_diff(sa, values))
                cmp["max_abs_diff_vs_stored"] = num(max_abs_diff(sa, st))
                cmp["voxels_differing_from_values"] = int(np.count_nonzero(sa != values))
            else:
                cmp["shape_mismatch"] = (f"SimpleITK {list(sa.shape)} vs pydicom "
                                         f"{list(values.shape)}")
            svs["comparison"] = cmp
            svs["pixel_type"] = srec.get("pixel_type")
            rec["values_simpleitk"] = svs
            if dgs is not None and cmp.get("max_abs_diff_vs_stored") == 0:
                notes.append("SimpleITK returns the stored integers: it does NOT apply "
                             "DoseGridScaling")
            elif dgs is not None and cmp.get("max_abs_diff_vs_values", 1) <= VALUE_TOL:
                notes.append("SimpleITK applies DoseGridScaling")
            elif (int(ds_get(ds, "BitsAllocated", 0)) == 1 and sa.shape == values.shape
                  and np.array_equal(sa, values * 255)):
                notes.append("SimpleITK (GDCM) gives 0/255 for the 1-bit pixels, pydicom 0/1")
            elif cmp.get("max_abs_diff_vs_values", 0) > VALUE_TOL:
                notes.append(f"SimpleITK's values differ from pydicom's: max |diff| "
                             f"{cmp['max_abs_diff_vs_values']} in "
                             f"{cmp['voxels_differing_from_values']} of {values.size} voxels")
            elif "shape_mismatch" in cmp:
                notes.append("SimpleITK's value array has a different shape: "
                             + cmp["shape_mismatch"])
    elif has_pixels and sa is not None:
        # pydicom cannot decode, SimpleITK can: SimpleITK's values are the reference
        values = sa
        rec["stored_type"] = {"16-bit unsigned integer": "uint16",
                              "16-bit signed integer": "int16",
                              "8-bit unsigned integer": "uint8"}.get(srec.get("pixel_type"),
                                                                     srec.get("pixel_type"))
        v = stats(sa)
        v.update(spot_values(np.transpose(sa, (2, 1, 0))))
        rec["values"] = v
        rec["values_reader"] = (f"SimpleITK {sitk.Version_VersionString()} (pydicom cannot "
                                "decode the pixel data)")
        notes.append("pydicom cannot decode the pixel data; values are SimpleITK's")
    elif has_pixels:
        rec["values"] = None
        rec["values_reader"] = None
        # pydicom's expected vs available pixel bytes, for truncation
        try:
            bpp = int(ds.BitsAllocated) // 8 or 1
            expected = int(ds.Rows) * int(ds.Columns) * bpp * (nframes or 1) * int(
                ds_get(ds, "SamplesPerPixel", 1))
            got = len(ds.PixelData)
            if got < expected and (ts is None or not ts.is_compressed):
                notes.append(f"truncated: Pixel Data has {got} bytes, {expected} expected; "
                             "no reader gives values")
        except Exception:  # noqa: BLE001
            pass

    # --- file-specific checks that need the raw bytes
    if ds_bad and raw[:1] == b" ":
        try:
            alt = pydicom.dcmread(io.BytesIO(raw[1:]), force=True)
            desc = (f"{ds_get(alt, 'Modality')} {ds_get(alt, 'Columns')}x{ds_get(alt, 'Rows')}"
                    f" '{ds_get(alt, 'SOPClassUID', '')}'")
            notes.append("the file starts with a stray 0x20 byte; from byte 1 on it is a "
                         f"valid Explicit VR Little Endian dataset without file meta ({desc})")
            ct = os.path.join(os.path.dirname(path), "CT_small.dcm")
            if os.path.exists(ct):
                ctraw = open(ct, "rb").read()
                ctds = pydicom.dcmread(ct)
                # dataset bytes of CT_small start right after its file meta group
                start = ctraw.find(b"\x08\x00\x05\x00")
                if start > 0 and ctraw[start:] == raw[1:]:
                    notes.append("bytes 1.. are identical to CT_small.dcm's dataset after its "
                                 "file meta")
                del ctds
        except Exception:  # noqa: BLE001
            pass

    if errors:
        rec["errors"] = errors
    rec["notes"] = notes
    return rec, values


# ----------------------------------------------------------------------------------------
# NIfTI


def affine_geometry(A, shape3):
    A = np.asarray(A, dtype=np.float64)
    M = A[:3, :3]
    spacing = np.linalg.norm(M, axis=0)
    D = M / spacing[None, :]
    g = geometry_dict(shape3, spacing, A[:3, 3], D)
    # cross-check: index point straight from the affine
    for key, idx in (("1,2,0", (1, 2, 0)), (f"1,2,{shape3[2] - 1}", (1, 2, shape3[2] - 1))):
        if key in g["index_point"]:
            direct = (A @ np.array([*idx, 1.0]))[:3]
            assert np.allclose(direct, g["index_point"][key], atol=1e-6), (direct, key)
    g["determinant_sign"] = int(np.sign(np.linalg.det(M)))
    g["affine"] = clean(A[:3, :])
    return g


NIFTI_DT = {2: "uint8", 4: "int16", 8: "int32", 16: "float32", 64: "float64", 256: "int8",
            512: "uint16", 768: "uint32", 1024: "int64", 1280: "uint64"}


def read_nifti(path):
    raw_len = os.path.getsize(path)
    rec = {"bytes": raw_len, "sha256": sha256(path), "gzip": path.endswith(".gz")}
    notes = []
    errors = {}
    try:
        img = nib.load(path)
    except Exception as e:  # noqa: BLE001
        errors["nibabel"] = short_error(e)
        rec["errors"] = errors
        rec["notes"] = notes
        srec, _ = sitk_read(path)
        rec["geometry_simpleitk"] = srec
        return rec
    rec["format"] = "NIfTI-2" if isinstance(img, nib.Nifti2Image) else (
        "NIfTI-1" if isinstance(img, nib.Nifti1Image) else type(img).__name__)

    # raw header as stored in the file (img.header has scl_* reset to NaN by nibabel)
    with nib.openers.ImageOpener(path) as fobj:
        hdr = type(img.header).from_fileobj(fobj)
    dim = [int(d) for d in hdr["dim"]]
    ndim = dim[0]
    shape = img.shape
    dt = int(hdr["datatype"])
    rec["header"] = {
        "endianness": "big" if hdr.endianness == ">" else "little",
        "datatype": dt,
        "bitpix": int(hdr["bitpix"]),
        "dim": dim,
        "pixdim": clean([float(p) for p in hdr["pixdim"]]),
        "vox_offset": num(hdr["vox_offset"]),
        "scl_slope": num(hdr["scl_slope"]),
        "scl_inter": num(hdr["scl_inter"]),
        "xyzt_units": list(hdr.get_xyzt_units()),
        "sform_code": int(hdr["sform_code"]),
        "qform_code": int(hdr["qform_code"]),
        "quatern_bcd": clean([float(hdr["quatern_b"]), float(hdr["quatern_c"]),
                              float(hdr["quatern_d"])]),
        "qfac": num(hdr["pixdim"][0]),
        "descrip": bytes(hdr["descrip"]).split(b"\0")[0].decode("latin-1"),
    }
    rec["stored_type"] = NIFTI_DT.get(dt, str(img.get_data_dtype()))
    if hdr.endianness == ">":
        notes.append("big-endian file")
    slope, inter = img.dataobj.slope, img.dataobj.inter
    rec["rescale"] = {"slope": num(slope), "intercept": num(inter),
                      "applied": bool(slope != 1 or inter != 0),
                      "how": "nibabel get_fdata() (scl_slope 0 or NaN means no scaling)"}

    shape3 = (list(shape) + [1, 1, 1])[:3]
    nframes = shape[3] if len(shape) > 3 else 1
    if len(shape) > 4:
        notes.append(f"{len(shape)}-D image; only the first 4 dims are described")
    rec["size"] = shape3
    if len(shape) > 3:
        rec["size_4d"] = int(shape[3])
        rec["spacing_4d"] = num(hdr["pixdim"][4])

    sform = affine_geometry(hdr.get_sform(), shape3)
    sform["code"] = int(hdr["sform_code"])
    qform = affine_geometry(hdr.get_qform(), shape3)
    qform["code"] = int(hdr["qform_code"])
    if qform["code"] == 0:
        qform["note"] = ("qform_code 0: nibabel's get_qform() still builds this matrix from "
                         "pixdim and the quaternion; NIfTI 'method 1' would use pixdim only")
    if sform["code"] == 0:
        sform["note"] = "sform_code 0: not valid"
    rec["sform"] = sform
    rec["qform"] = qform
    aff = np.asarray(img.affine, dtype=np.float64)
    uses = []
    if sform["code"] > 0 and np.allclose(aff, hdr.get_sform(), atol=1e-9):
        uses = ["sform"]
    elif qform["code"] > 0 and np.allclose(aff, hdr.get_qform(), atol=1e-9):
        uses = ["qform"]
    else:
        uses = ["neither (base affine from pixdim)"]
    rec["nibabel_affine_uses"] = uses[0]
    sq_diff = float(np.max(np.abs(np.asarray(hdr.get_sform()) - np.asarray(hdr.get_qform()))))
    rec["sform_qform_max_abs_diff"] = num(sq_diff)
    if sq_diff > 0:
        notes.append(f"sform and qform matrices differ (max |diff| {sq_diff:.3g})")

    g = affine_geometry(aff, shape3)
    for k in ("spacing", "origin", "direction", "index_point"):
        rec[k] = g[k]
    rec["determinant_sign"] = g["determinant_sign"]
    rec["reader"] = f"nibabel {nib.__version__} (img.affine = {uses[0]})"

    # values
    data = img.get_fdata(dtype=np.float64)
    if data.ndim == 2:
        data = data[:, :, None]
    rec["values_reader"] = f"nibabel {nib.__version__} get_fdata()"
    if data.ndim == 3:
        v = stats(data)
        v.update(spot_values(data))
        rec["values"] = v
    else:
        d4 = data.reshape(data.shape[:3] + (-1,))
        v0 = stats(d4[..., 0])
        v0.update(spot_values(d4[..., 0]))
        vl = stats(d4[..., -1])
        vl.update(spot_values(d4[..., -1]))
        rec["values_frame0"] = v0
        rec["values_last_frame"] = vl
        rec["values_all_frames"] = stats(d4)
        notes.append(f"4-D: {nframes} frames along the 4th axis (pixdim[4] "
                     f"{float(hdr['pixdim'][4]):g} {hdr.get_xyzt_units()[1]})")

    # SimpleITK
    srec, sarr = sitk_read(path)
    rec["geometry_simpleitk"] = srec
    if "error" in srec:
        errors["simpleitk"] = srec["error"]
        notes.append("SimpleITK cannot read this file")
    else:
        matches = [name for name, gg in (("sform", sform), ("qform", qform))
                   if gg["code"] > 0 and not compare_geometry(srec, gg)]
        srec["matches"] = matches or ["neither"]
        if not matches:
            notes.append("SimpleITK geometry matches neither the sform nor the qform: "
                         + "; ".join(compare_geometry(srec, g)))
        elif matches == ["qform"] and uses[0] == "sform":
            notes.append("SimpleITK takes the qform while nibabel takes the sform")
        sa = np.asarray(sarr, dtype=np.float64)
        # ITK array is [t, z, y, x] / [z, y, x]; nibabel's is [x, y, z, t]
        sa = np.transpose(sa, tuple(range(sa.ndim - 1, -1, -1)))
        if sa.shape == data.shape:
            nan_n, nan_s = np.isnan(data), np.isnan(sa)
            if not np.array_equal(nan_n, nan_s):
                only = nan_n & ~nan_s
                repl = np.unique(sa[only])
                srec["nan_voxels_nibabel_not_simpleitk"] = int(only.sum())
                notes.append(f"nibabel gives NaN in {int(nan_n.sum())} voxels; SimpleITK gives "
                             f"{', '.join(f'{x:g}' for x in repl[:3])} in {int(only.sum())} of "
                             f"them (NaN in {int((nan_s & nan_n).sum())})")
                both = ~nan_n & ~nan_s
                diff = max_abs_diff(sa[both], data[both])
            else:
                diff = max_abs_diff(sa, data)
            srec["values_max_abs_diff_vs_nibabel"] = num(diff)
            rel = diff / max(1.0, float(np.nanmax(np.abs(data))))
            if rel > 1e-6:
                notes.append(f"SimpleITK's values differ from nibabel's (max |diff| {diff:.3g})")
            elif diff > 0:
                notes.append(f"SimpleITK's values ({srec['pixel_type']}) agree with nibabel's "
                             f"to float32 rounding (max |diff| {diff:.3g})")
        else:
            srec["values_shape_mismatch"] = f"{list(sa.shape)} vs {list(data.shape)}"
            notes.append("SimpleITK's value array has a different shape")

    if errors:
        rec["errors"] = errors
    rec["notes"] = notes
    return rec


# ----------------------------------------------------------------------------------------


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__.split("Run,")[1])
    data = sys.argv[1]
    rt = os.path.join(data, "reader_tests")
    dicom_dir = os.path.join(rt, "pydicom_test_files")
    nifti_dir = os.path.join(rt, "nibabel_test_data")
    out = {
        "description": "Reference geometry and values for the pydicom and nibabel test files in "
                       "shared data reader_tests/, made by make_reader_reference.py",
        "convention": (
            "size [nx, ny, nz], x fastest (DICOM: Columns, Rows, frames); world point of index "
            "(i,j,k) = origin + D @ (spacing * (i,j,k)); direction = rows of D, whose columns are "
            "unit axis directions; world frame RAS+ (DICOM/ITK LPS with x and y negated); "
            "index_point = world point of (1,2,0) and, when nz > 1, of (1,2,nz-1); values after "
            "the modality rescale (DICOM RescaleSlope/Intercept, RT Dose also DoseGridScaling; "
            "NIfTI scl_slope/scl_inter); min/max/mean/sum float64 over all voxels; at_last = "
            "value at (nx-1, ny-1, nz-1), at_mid at (nx//2, ny//2, nz//2)"),
        "versions": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "pydicom": pydicom.__version__,
            "SimpleITK": sitk.Version_VersionString(),
            "nibabel": nib.__version__,
            "pylibjpeg": pkg_version("pylibjpeg"),
            "pylibjpeg-libjpeg": pkg_version("pylibjpeg-libjpeg"),
            "pylibjpeg-openjpeg": pkg_version("pylibjpeg-openjpeg"),
            "pyjpegls": pkg_version("pyjpegls"),
        },
        "files": {},
    }

    values_by_file = {}
    for name in sorted(os.listdir(dicom_dir)):
        if name in ("LICENSE", "README.txt") or name.startswith("."):
            continue
        path = os.path.join(dicom_dir, name)
        rec, vals = read_dicom(path, data)
        out["files"][f"pydicom_test_files/{name}"] = rec
        if vals is not None:
            values_by_file[name] = vals

    # which DICOM files decode to identical values
    names = sorted(values_by_file)
    for a in names:
        same = [b for b in names if b != a and values_by_file[b].shape == values_by_file[a].shape
                and np.array_equal(values_by_file[b], values_by_file[a])]
        if same:
            out["files"][f"pydicom_test_files/{a}"]["same_values_as"] = same
        near = []
        for b in names:
            if b == a or b in same or values_by_file[b].shape != values_by_file[a].shape:
                continue
            d = max_abs_diff(values_by_file[b], values_by_file[a])
            if d <= 4:
                n = int(np.count_nonzero(values_by_file[b] != values_by_file[a]))
                near.append(f"{b} (max |diff| {d:g} in {n} voxels)")
        if near:
            out["files"][f"pydicom_test_files/{a}"]["near_values_as"] = near

    for name in sorted(os.listdir(nifti_dir)):
        if not (name.endswith(".nii") or name.endswith(".nii.gz")):
            continue
        out["files"][f"nibabel_test_data/{name}"] = read_nifti(os.path.join(nifti_dir, name))

    first = ["format", "bytes", "sha256", "transfer_syntax", "frames", "size", "size_4d",
             "spacing", "origin", "direction", "index_point", "reader", "stored_type",
             "rescale", "values", "values_frame0", "values_last_frame", "values_all_frames",
             "values_reader", "notes", "errors"]
    for key, rec in out["files"].items():
        out["files"][key] = {k: rec[k] for k in first if k in rec} | {
            k: v for k, v in rec.items() if k not in first}
    sys.stdout.write(to_json(out) + "\n")


def to_json(x, indent=0):
    """JSON with one key per line but lists of scalars (and of short lists) on one line."""
    pad = " " * indent

    def flat(v):
        return not isinstance(v, (dict, list)) or (
            isinstance(v, list) and all(not isinstance(e, (dict, list)) for e in v))

    if isinstance(x, dict):
        if not x:
            return "{}"
        items = [f'{pad} {json.dumps(k)}: {to_json(v, indent + 1)}' for k, v in x.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(x, list) and all(flat(e) for e in x):
        return json.dumps(x)
    if isinstance(x, list):
        items = [f"{pad} {to_json(v, indent + 1)}" for v in x]
        return "[\n" + ",\n".join(items) + "\n" + pad + "]"
    return json.dumps(x)


if __name__ == "__main__":
    main()
