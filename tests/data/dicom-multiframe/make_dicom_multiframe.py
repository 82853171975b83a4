"""Writes the multi-frame DICOM test files in this folder and records reference geometry.

Files:
  legacy-enhanced-ct.dcm  Legacy Converted Enhanced CT Image (one file, 3 frames of 8x6 pixels),
                          made by highdicom's LegacyConvertedEnhancedCTImage from a synthetic
                          3-slice single-frame CT series built in memory with pydicom.
  rtdose.dcm              RT Dose (pydicom-built), 3 frames of 4x3 pixels, uint32, with
                          GridFrameOffsetVector and DoseGridScaling 0.001.

Shared geometry (DICOM patient space, LPS):
  ImageOrientationPatient = R[:, 0] and R[:, 1] for R = Rx(20 deg) @ Rz(30 deg), oblique and
  non-symmetric: the row direction (towards increasing column index, x) is R[:, 0] and the
  column direction (towards increasing row index, y) is R[:, 1]; the slice normal is their
  cross product, R[:, 2].
  PixelSpacing = [0.75, 0.5]: 0.75 mm between rows (y spacing), 0.5 mm between columns (x).
  First frame's ImagePositionPatient (10, -20, 30); frames 2 mm apart along the normal.

Values:
  CT: stored uint16 = 5 i + 994 for voxel id i = x + 8 (y + 6 z); RescaleSlope 1,
      RescaleIntercept -1024, so HU = 5 i - 30.
  RT dose: stored uint32 = 100 i + 50 for i = x + 4 (y + 3 z); dose = 0.001 * stored Gy.

highdicom stores the CT frames in DECREASING position along the slice normal (its input was in
increasing order; pixel data and PlanePositionSequence are reordered together), so frame 0 is
the input's last slice and the third axis of the file's own order points along -normal. The
reference follows the file's frame order, as SimpleITK does.

Reference geometry is computed by hand from the tags as written (see frame_geometry()) and
converted to RAS (x and y negated); it is cross-checked against SimpleITK (GDCM), whose
reading is recorded too, converted to RAS.

Made with Python 3.11, numpy 2.4.6, pydicom 3.0.2, highdicom 0.28.2, SimpleITK 2.5.7
(pip install numpy pydicom highdicom SimpleITK). Run from anywhere: python3 make_dicom_multiframe.py
"""
import json
import math
import os
import re

import highdicom as hd
import numpy as np
import pydicom
import SimpleITK as sitk
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import ExplicitVRLittleEndian, generate_uid

HERE = os.path.dirname(os.path.abspath(__file__))
FLIP = np.diag([-1.0, -1.0, 1.0])  # LPS <-> RAS
PROBE = (1, 2, 1)
PROBE2 = (1, 2, 2)  # (1, 2, 1) is the middle frame of 3, so it cannot show the frame order; this can
ORIGIN = np.array([10.0, -20.0, 30.0])  # LPS
PIXEL_SPACING = [0.75, 0.5]  # [row spacing (y), column spacing (x)]
SLICE_GAP = 2.0


def rot(axis, deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


R = rot("x", 20) @ rot("z", 30)
IOP = [float(v) for v in np.concatenate([R[:, 0], R[:, 1]])]


def uid(name):
    """Reproducible UIDs."""
    return generate_uid(entropy_srcs=["splatscene tests/data/dicom-multiframe", name])


STUDY, FOR = uid("study"), uid("frame-of-reference")


def base_dataset(sop_class, sop_instance, modality):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class
    meta.MediaStorageSOPInstanceUID = sop_instance
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = sop_instance
    ds.Modality = modality
    ds.PatientName = "Test^Volume"
    ds.PatientID = "SPLATSCENE-TEST"
    ds.PatientBirthDate = ""
    ds.PatientSex = "O"
    ds.StudyInstanceUID = STUDY
    ds.StudyDate = "20240101"
    ds.StudyTime = "120000"
    ds.StudyID = "1"
    ds.AccessionNumber = ""
    ds.ReferringPhysicianName = ""
    ds.FrameOfReferenceUID = FOR
    ds.PositionReferenceIndicator = ""
    ds.Manufacturer = "splatscene test data"
    ds.ImageOrientationPatient = IOP
    ds.PixelSpacing = PIXEL_SPACING
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    return ds


def ct_series():
    nx, ny, nz = 8, 6, 3
    stored = (np.arange(nx * ny * nz) * 5 + 994).astype(np.uint16).reshape(nz, ny, nx)
    series = uid("ct-series")
    out = []
    for k in range(nz):
        ds = base_dataset(pydicom.uid.CTImageStorage, uid("ct-slice-%d" % k), "CT")
        ds.SeriesInstanceUID = series
        ds.SeriesNumber = 1
        ds.InstanceNumber = k + 1
        ds.ImageType = ["ORIGINAL", "PRIMARY", "AXIAL"]
        ds.ContentDate, ds.ContentTime = "20240101", "120000"
        ds.AcquisitionNumber = 1
        ds.KVP = 120
        ds.ImagePositionPatient = [float(v) for v in ORIGIN + k * SLICE_GAP * R[:, 2]]
        ds.SliceThickness = SLICE_GAP
        ds.Rows, ds.Columns = ny, nx
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 0
        ds.RescaleIntercept, ds.RescaleSlope, ds.RescaleType = -1024, 1, "HU"
        ds.WindowCenter, ds.WindowWidth = 40, 400
        ds.PixelData = stored[k].tobytes()
        out.append(ds)
    return out


def write_ct():
    legacy = ct_series()
    mf = hd.legacy.LegacyConvertedEnhancedCTImage(
        legacy_datasets=legacy,
        series_instance_uid=uid("ct-enhanced-series"),
        series_number=2,
        sop_instance_uid=uid("ct-enhanced"),
        instance_number=1,
    )
    mf.save_as(os.path.join(HERE, "legacy-enhanced-ct.dcm"), enforce_file_format=True)


def write_rtdose():
    nx, ny, nz = 4, 3, 3
    offsets = [0.0, 2.0, 4.0]  # GridFrameOffsetVector, relative to ImagePositionPatient (first is 0)
    ds = base_dataset(pydicom.uid.RTDoseStorage, uid("rtdose"), "RTDOSE")
    ds.SeriesInstanceUID = uid("rtdose-series")
    ds.SeriesNumber = 3
    ds.InstanceNumber = 1
    ds.ImagePositionPatient = [float(v) for v in ORIGIN]
    ds.SliceThickness = None
    ds.Rows, ds.Columns = ny, nx
    ds.NumberOfFrames = nz
    ds.FrameIncrementPointer = pydicom.tag.Tag(0x3004, 0x000C)
    ds.GridFrameOffsetVector = offsets
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 32, 32, 31, 0
    ds.DoseUnits, ds.DoseType, ds.DoseSummationType = "GY", "PHYSICAL", "PLAN"
    ds.DoseGridScaling = 0.001
    stored = (np.arange(nx * ny * nz) * 100 + 50).astype("<u4")
    ds.PixelData = stored.tobytes()
    ds.save_as(os.path.join(HERE, "rtdose.dcm"), enforce_file_format=True)


def frame_geometry(iop, pixel_spacing, positions):
    """Reference geometry from the tags, in LPS then RAS.

    x axis (column index) direction = IOP[0:3], y axis (row index) = IOP[3:6],
    spacing x = PixelSpacing[1], spacing y = PixelSpacing[0];
    normal n = IOP[0:3] x IOP[3:6]; the z axis runs from frame 0 to frame 1, so
    spacing z = (P1 - P0) . n and direction z = n (sign of that dot product); origin = P0;
    point(i,j,k) = P0 + i sx u + j sy v + k sz n.

    Worked for rtdose.dcm (frames in increasing offset order), LPS:
      u = (0.8660, 0.4698, 0.1710), v = (-0.5, 0.8138, 0.2962), n = u x v = (0, -0.3420, 0.9397)
      offsets 0, 2, 4 -> frame positions P0 + 0 n, P0 + 2 n, P0 + 4 n; sz = 2
      point(1,2,1) = (10, -20, 30) + 1*0.5 u + 2*0.75 v + 1*2 n
                   = (10 + 0.4330 - 0.75 + 0, -20 + 0.2349 + 1.2207 - 0.6840, 30 + 0.0855 + 0.4443 + 1.8794)
                   = (9.6830, -19.2284, 32.4092) LPS = (-9.6830, 19.2284, 32.4092) RAS.
    For legacy-enhanced-ct.dcm the frames run the other way (P0 = (10, -20, 30) + 4 n), so the
    third direction is -n and point(1,2,1) is the same point (the middle frame)."""
    iop = np.asarray(iop, dtype=float)
    u, v = iop[:3], iop[3:]
    n = np.cross(u, v)
    p = np.asarray(positions, dtype=float)
    steps = (p[1:] - p[:-1]) @ n
    assert np.allclose(steps, steps[0]), steps  # regular grid
    sz = float(steps[0])
    w = n if sz > 0 else -n
    sx, sy = float(pixel_spacing[1]), float(pixel_spacing[0])
    d_lps = np.column_stack([u, v, w])
    pt = p[0] + d_lps @ (np.array([sx, sy, abs(sz)]) * np.array(PROBE))
    pt2 = p[0] + d_lps @ (np.array([sx, sy, abs(sz)]) * np.array(PROBE2))
    # off-normal drift between frames must be zero for a regular grid
    assert np.allclose(p - p[0], np.outer((p - p[0]) @ n, n), atol=1e-6)
    return {
        "reader": "by hand from the tags (frame_geometry in make_dicom_multiframe.py), LPS converted to RAS",
        "spacing": [sx, sy, abs(sz)],
        "origin": (FLIP @ p[0]).tolist(),
        "direction": (FLIP @ d_lps).tolist(),
        "point_1_2_1": (FLIP @ pt).tolist(),
        "point_1_2_2": (FLIP @ pt2).tolist(),
        "lps": {"origin": p[0].tolist(), "direction": d_lps.tolist(), "point_1_2_1": pt.tolist(),
                "point_1_2_2": pt2.tolist()},
    }


def from_sitk(name):
    im = sitk.ReadImage(name)
    v = sitk.GetArrayFromImage(im)
    d = np.array(im.GetDirection()).reshape(3, 3)
    return {
        "reader": "SimpleITK %s (GDCM; ITK LPS converted to RAS)" % sitk.Version.VersionString(),
        "size": list(im.GetSize()),
        "spacing": list(im.GetSpacing()),
        "origin": (FLIP @ np.array(im.GetOrigin())).tolist(),
        "direction": (FLIP @ d).tolist(),
        "point_1_2_1": (FLIP @ np.array(im.TransformIndexToPhysicalPoint(PROBE))).tolist(),
        "point_1_2_2": (FLIP @ np.array(im.TransformIndexToPhysicalPoint(PROBE2))).tolist(),
        "pixel_type": im.GetPixelIDTypeAsString(),
        "values": {"sum": float(v.sum()), "min": float(v.min()), "max": float(v.max())},
        "value_at_1_2_1": float(v[PROBE[2], PROBE[1], PROBE[0]]),
        "value_at_1_2_2": float(v[PROBE2[2], PROBE2[1], PROBE2[0]]),
    }


def describe_ct(name):
    ds = pydicom.dcmread(name)
    shared = ds.SharedFunctionalGroupsSequence[0]
    per = ds.PerFrameFunctionalGroupsSequence

    def group(i, attr):
        item = per[i]
        return getattr(item, attr)[0] if attr in item else getattr(shared, attr)[0]

    positions = [[float(x) for x in group(i, "PlanePositionSequence").ImagePositionPatient] for i in range(len(per))]
    iops = {tuple(float(x) for x in group(i, "PlaneOrientationSequence").ImageOrientationPatient) for i in range(len(per))}
    assert len(iops) == 1
    iop = list(iops.pop())
    meas = group(0, "PixelMeasuresSequence")
    trans = group(0, "PixelValueTransformationSequence")
    slope, inter = float(trans.RescaleSlope), float(trans.RescaleIntercept)
    stored = ds.pixel_array.astype(np.int64)  # (frames, rows, columns)
    hu = stored * slope + inter
    return {
        "bytes": os.path.getsize(name),
        "sop_class": "%s (%s)" % (ds.SOPClassUID.name, ds.SOPClassUID),
        "transfer_syntax": str(ds.file_meta.TransferSyntaxUID.name),
        "size": [int(ds.Columns), int(ds.Rows), int(ds.NumberOfFrames)],
        "stored_type": "uint16 (BitsAllocated %d, PixelRepresentation %d)" % (ds.BitsAllocated, ds.PixelRepresentation),
        "image_orientation_patient": iop,
        "pixel_spacing": [float(x) for x in meas.PixelSpacing],
        "slice_thickness": float(meas.SliceThickness) if "SliceThickness" in meas else None,
        "per_frame_image_position_patient": positions,
        "rescale": {"slope": slope, "intercept": inter,
                    "where": "PixelValueTransformationSequence in %s functional groups"
                             % ("per-frame" if "PixelValueTransformationSequence" in per[0] else "shared")},
        "stored_values": {"sum": int(stored.sum()), "min": int(stored.min()), "max": int(stored.max())},
        "values": {"sum": float(hu.sum()), "min": float(hu.min()), "max": float(hu.max()), "unit": "HU"},
        "value_at_1_2_1": float(hu[PROBE[2], PROBE[1], PROBE[0]]),
        "value_at_1_2_2": float(hu[PROBE2[2], PROBE2[1], PROBE2[0]]),
        "first_stored_value_per_frame": [int(x) for x in stored[:, 0, 0]],
        "geometry": {"tags": frame_geometry(iop, meas.PixelSpacing, positions), "simpleitk": from_sitk(name)},
    }


def describe_rtdose(name):
    ds = pydicom.dcmread(name)
    ipp = np.array([float(x) for x in ds.ImagePositionPatient])
    iop = [float(x) for x in ds.ImageOrientationPatient]
    n = np.cross(iop[:3], iop[3:])
    offsets = [float(x) for x in ds.GridFrameOffsetVector]
    # GridFrameOffsetVector with first element 0: offsets along the normal from ImagePositionPatient.
    positions = [(ipp + o * n).tolist() for o in offsets]
    stored = ds.pixel_array.astype(np.int64)
    dose = stored * float(ds.DoseGridScaling)
    return {
        "bytes": os.path.getsize(name),
        "sop_class": "%s (%s)" % (ds.SOPClassUID.name, ds.SOPClassUID),
        "transfer_syntax": str(ds.file_meta.TransferSyntaxUID.name),
        "size": [int(ds.Columns), int(ds.Rows), int(ds.NumberOfFrames)],
        "stored_type": "uint32 (BitsAllocated %d, PixelRepresentation %d)" % (ds.BitsAllocated, ds.PixelRepresentation),
        "image_orientation_patient": iop,
        "pixel_spacing": [float(x) for x in ds.PixelSpacing],
        "image_position_patient": ipp.tolist(),
        "grid_frame_offset_vector": offsets,
        "frame_positions_from_offsets": positions,
        "dose_grid_scaling": float(ds.DoseGridScaling),
        "stored_values": {"sum": int(stored.sum()), "min": int(stored.min()), "max": int(stored.max())},
        "values": {"sum": float(dose.sum()), "min": float(dose.min()), "max": float(dose.max()), "unit": "Gy"},
        "value_at_1_2_1": float(dose[PROBE[2], PROBE[1], PROBE[0]]),
        "value_at_1_2_2": float(dose[PROBE2[2], PROBE2[1], PROBE2[0]]),
        "first_stored_value_per_frame": [int(x) for x in stored[:, 0, 0]],
        "geometry": {"tags": frame_geometry(iop, ds.PixelSpacing, positions), "simpleitk": from_sitk(name)},
    }


def dump_json(obj, path):
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    write_ct()
    write_rtdose()
    files = {"legacy-enhanced-ct.dcm": describe_ct("legacy-enhanced-ct.dcm"), "rtdose.dcm": describe_rtdose("rtdose.dcm")}
    ref = {
        "convention": "dims [nx, ny, nz] = [Columns, Rows, frames], x fastest; world point of index (i,j,k) = "
                      "origin + D * (spacing * (i,j,k)); direction rows are the rows of D; RAS (DICOM's LPS "
                      "with x and y negated); values after rescale (CT) or DoseGridScaling (RT dose)",
        "written_by": "pydicom %s, highdicom %s (make_dicom_multiframe.py)" % (pydicom.__version__, hd.__version__),
        "files": files,
    }
    dump_json(ref, "reference.json")
    for n, d in files.items():
        g = d["geometry"]
        print(n, d["bytes"], "bytes; tags (1,2,1):", np.round(g["tags"]["point_1_2_1"], 6).tolist(),
              "SimpleITK:", np.round(g["simpleitk"]["point_1_2_1"], 6).tolist(), g["simpleitk"]["spacing"],
              "values", d["values"], "sitk", g["simpleitk"]["values"])


if __name__ == "__main__":
    main()
