//! Crafted inputs, as an attacker or a careless user would give them, each run through the
//! real command line under a time limit (10 s, a hang detector: each case takes well under a
//! second here) and an address-space limit (8 GiB, far below what the wrapped sizes and
//! oversized buffers these cases declare would take), with a memory budget of 256 MiB
//! (`SPLATSCENE_MEMORY_LIMIT`, so that what is refused does not depend on the machine): every
//! one must end in a clear error that names the file or key and the problem, in words meant for
//! people (no Rust debug text), with no panic and no hang, or in a correct result; and the
//! files the user had must be as they were unless the command names them as its output. The
//! inputs are generated here (a named pipe `fifo` and a link `zero` to `/dev/zero` in every
//! case's folder); nothing large is stored.
//!
//! One file on purpose, past the usual length: it is the catalogue of crafted cases (more than
//! 150, a format at a time), read as one list; what runs them is the short end of the file.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

mod common;

/// What a case must end in.
enum Expect {
    /// Failure, with each of these words in the message.
    Error(Vec<String>),
    /// Success.
    Ok,
}

/// A check of a case's folder after the run: what must hold, or what went wrong.
type AfterCheck = fn(&Path) -> Result<(), String>;

/// One crafted input: files written into its own folder, the command line run there
/// (`{dir}` stands for that folder), and what must come of it.
struct Case {
    name: String,
    files: Vec<(String, Vec<u8>)>,
    args: Vec<String>,
    expect: Expect,
    /// What must hold of the case's folder afterwards.
    after: Option<AfterCheck>,
    /// Links and folders made in the case's folder before the run.
    setup: Option<fn(&Path)>,
}

fn case(name: &str, files: Vec<(&str, Vec<u8>)>, args: &[&str], words: &[&str]) -> Case {
    Case {
        name: name.into(),
        files: files.into_iter().map(|(n, b)| (n.into(), b)).collect(),
        args: args.iter().map(|a| a.to_string()).collect(),
        expect: Expect::Error(words.iter().map(|w| w.to_string()).collect()),
        after: None,
        setup: None,
    }
}

fn works(name: &str, files: Vec<(&str, Vec<u8>)>, args: &[&str]) -> Case {
    Case {
        expect: Expect::Ok,
        ..case(name, files, args, &[])
    }
}

/// `info` on one file, which must fail with these words (the file name is required too).
fn info(name: &str, file: &str, bytes: Vec<u8>, words: &[&str]) -> Case {
    let mut all = vec![file];
    all.extend(words);
    case(name, vec![(file, bytes)], &["info", file], &all)
}

// ---- NRRD ----------------------------------------------------------------------------------

fn nrrd(fields: &[(&str, &str)], data: &[u8]) -> Vec<u8> {
    let mut defaults = vec![
        ("type", "short"),
        ("dimension", "3"),
        ("sizes", "2 2 2"),
        ("encoding", "raw"),
        ("endian", "little"),
    ];
    for (key, value) in fields {
        match defaults.iter_mut().find(|(k, _)| k == key) {
            Some(slot) => slot.1 = value,
            None => defaults.push((key, value)),
        }
    }
    let mut text = String::from("NRRD0004\n");
    for (k, v) in defaults.iter().filter(|(_, v)| !v.is_empty()) {
        text.push_str(&format!("{k}: {v}\n"));
    }
    text.push('\n');
    let mut bytes = text.into_bytes();
    bytes.extend(data);
    bytes
}

fn nrrd_cases() -> Vec<Case> {
    let data = [0u8; 16];
    let bad: &[(&str, &str, &str, &[&str])] = &[
        ("sizes-zero", "sizes", "0 2 2", &["axis without voxels"]),
        ("sizes-negative", "sizes", "-1 2 2", &["sizes"]),
        ("sizes-wrap", "sizes", "2147483648 2147483648 4", &["grid"]),
        ("sizes-huge", "sizes", "99999999999 2 2", &["sizes"]),
        ("sizes-two", "sizes", "2 2", &["sizes"]),
        ("sizes-four", "sizes", "2 2 2 2", &["sizes"]),
        ("sizes-words", "sizes", "a b c", &["sizes"]),
        ("type-complex", "type", "complex", &["type"]),
        ("type-int64", "type", "int64", &["int64"]),
        ("type-empty", "type", "", &["type"]),
        ("encoding-hex", "encoding", "hex", &["hex"]),
        ("encoding-zip", "encoding", "zip", &["encoding"]),
        ("encoding-gzip-garbage", "encoding", "gzip", &[]),
        ("encoding-bzip2-garbage", "encoding", "bzip2", &[]),
        ("dimension-four", "dimension", "4", &["4-D"]),
        ("dimension-zero", "dimension", "0", &["0-D"]),
        ("dimension-word", "dimension", "x", &["dimension"]),
        ("spacings-zero", "spacings", "0 1 1", &[]),
        ("spacings-inf", "spacings", "inf 1 1", &[]),
        (
            "directions-zero",
            "space directions",
            "(0,0,0) (0,1,0) (0,0,1)",
            &[],
        ),
        (
            "directions-nan",
            "space directions",
            "(nan,0,0) (0,1,0) (0,0,1)",
            &[],
        ),
        (
            "directions-flat",
            "space directions",
            "(1,0,0) (1,0,0) (0,0,1)",
            &["span"],
        ),
        (
            "directions-short",
            "space directions",
            "(1,0) (0,1,0) (0,0,1)",
            &["space directions"],
        ),
        ("origin-nan", "space origin", "(nan,0,0)", &[]),
        (
            "data-file-missing",
            "data file",
            "missing.raw",
            &["missing.raw"],
        ),
        (
            "data-file-pattern-huge",
            "data file",
            "p%d.raw 0 4294967296 1",
            &["pattern"],
        ),
        ("data-file-device", "data file", "/dev/zero", &["zero"]),
        ("byte-skip-negative", "byte skip", "-5", &["byte skip"]),
        ("byte-skip-huge", "byte skip", "99999999999", &[]),
        ("line-skip-many", "line skip", "99", &["line skip"]),
        ("endian-middle", "endian", "middle", &["endian"]),
        ("space-unknown", "space", "sideways", &["space"]),
    ];
    let mut cases: Vec<Case> = bad
        .iter()
        .map(|(name, key, value, words)| {
            let mut with_space = vec![(*key, *value)];
            if key.starts_with("space ") {
                with_space.push(("space", "left-posterior-superior"));
            }
            let bytes = nrrd(&with_space, &data);
            info(&format!("nrrd-{name}"), "v.nrrd", bytes, words)
        })
        .collect();
    cases.push(info(
        "nrrd-short-data",
        "v.nrrd",
        nrrd(&[], &data[..8]),
        &["93 bytes"],
    ));
    // teem writes `nan` for a spacing it does not know; ITK then takes 1, as this does.
    let mut unknown = nrrd(&[("spacings", "nan 1 1")], &[]);
    unknown.extend([0u8; 16]);
    cases.push(works(
        "nrrd-spacings-nan",
        vec![("v.nrrd", unknown)],
        &["info", "v.nrrd"],
    ));
    cases.push(info(
        "nrrd-header-only",
        "v.nrrd",
        b"NRRD0004\n".to_vec(),
        &[],
    ));
    cases.push(info(
        "nrrd-no-blank-line",
        "v.nrrd",
        b"NRRD0004\ntype: short\nsizes: 2 2 2\n".to_vec(),
        &[],
    ));
    cases.push(info(
        "nrrd-binary-header",
        "v.nrrd",
        [b"NRRD0004\n".as_slice(), &[0xff; 64]].concat(),
        &["text"],
    ));
    let mut good = nrrd(&[], &[]);
    good.extend((0..8i16).flat_map(|v| v.to_le_bytes()));
    cases.push(works(
        "nrrd-good",
        vec![("v.nrrd", good)],
        &["info", "v.nrrd"],
    ));
    cases
}

// ---- NIfTI ---------------------------------------------------------------------------------

/// A NIfTI-1 file of 2x2x2 int16 with unit pixdim, changed by `edit`.
fn nifti1(edit: &dyn Fn(&mut Vec<u8>)) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    for (i, d) in [3i16, 2, 2, 2, 1, 1, 1, 1].iter().enumerate() {
        h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&4i16.to_le_bytes());
    h[72..74].copy_from_slice(&16i16.to_le_bytes());
    for i in 0..8 {
        h[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes());
    h[344..348].copy_from_slice(b"n+1\0");
    h.extend([1u8; 16]);
    edit(&mut h);
    h
}

fn put_i16(h: &mut [u8], at: usize, v: i16) {
    h[at..at + 2].copy_from_slice(&v.to_le_bytes());
}

fn put_f32(h: &mut [u8], at: usize, v: f32) {
    h[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn nifti_cases() -> Vec<Case> {
    type Edit = Box<dyn Fn(&mut Vec<u8>)>;
    let edits: Vec<(&str, Edit, &[&str])> = vec![
        ("dim0-zero", Box::new(|h| put_i16(h, 40, 0)), &["dim[0]"]),
        ("dim0-eight", Box::new(|h| put_i16(h, 40, 8)), &["dim[0]"]),
        (
            "dim-negative",
            Box::new(|h| put_i16(h, 42, -1)),
            &["dim[1]"],
        ),
        (
            "dims-huge",
            Box::new(|h| (1..4).for_each(|i| put_i16(h, 40 + 2 * i, 32767))),
            &["grid"],
        ),
        (
            "datatype-unknown",
            Box::new(|h| put_i16(h, 70, 3)),
            &["datatype 3"],
        ),
        (
            "datatype-float128",
            Box::new(|h| put_i16(h, 70, 1536)),
            &["float128"],
        ),
        ("datatype-rgb", Box::new(|h| put_i16(h, 70, 128)), &["RGB"]),
        (
            "vox-offset-early",
            Box::new(|h| put_f32(h, 108, 100.0)),
            &["vox_offset"],
        ),
        (
            "vox-offset-huge",
            Box::new(|h| put_f32(h, 108, 1e20)),
            &["vox_offset"],
        ),
        (
            "vox-offset-nan",
            Box::new(|h| put_f32(h, 108, f32::NAN)),
            &["vox_offset"],
        ),
        (
            "vox-offset-fraction",
            Box::new(|h| put_f32(h, 108, 352.5)),
            &["vox_offset"],
        ),
        ("pixdim-zero", Box::new(|h| put_f32(h, 80, 0.0)), &[]),
        ("pixdim-nan", Box::new(|h| put_f32(h, 80, f32::NAN)), &[]),
        (
            "sform-nan",
            Box::new(|h| {
                put_i16(h, 254, 1);
                put_f32(h, 280, f32::NAN)
            }),
            &[],
        ),
        ("sform-singular", Box::new(|h| put_i16(h, 254, 1)), &[]),
        (
            "qform-nan",
            Box::new(|h| {
                put_i16(h, 252, 1);
                put_f32(h, 256, f32::NAN)
            }),
            &["quatern"],
        ),
        (
            "qoffset-inf",
            Box::new(|h| {
                put_i16(h, 252, 1);
                put_f32(h, 268, f32::INFINITY)
            }),
            &[],
        ),
        ("units-bad", Box::new(|h| h[123] = 5), &["xyzt_units"]),
        (
            "slope-inf",
            Box::new(|h| put_f32(h, 112, f32::INFINITY)),
            &["scl_slope"],
        ),
        (
            "slope-overflow",
            Box::new(|h| {
                put_f32(h, 112, 3e38);
                h[352..].fill(0x7f)
            }),
            &["scl_slope"],
        ),
        (
            "magic-bad",
            Box::new(|h| h[344..348].copy_from_slice(b"xyz\0")),
            &[],
        ),
        ("short-data", Box::new(|h| h.truncate(360)), &["bytes"]),
        ("header-cut", Box::new(|h| h.truncate(200)), &[]),
        (
            "dim5",
            Box::new(|h| {
                put_i16(h, 40, 5);
                put_i16(h, 50, 2)
            }),
            &["dim[5]"],
        ),
        (
            "pair-no-img",
            Box::new(|h| h[344..348].copy_from_slice(b"ni1\0")),
            &["missing"],
        ),
    ];
    let mut cases: Vec<Case> = edits
        .into_iter()
        .map(|(name, edit, words)| info(&format!("nifti-{name}"), "v.nii", nifti1(&*edit), words))
        .collect();
    cases.push(works(
        "nifti-good",
        vec![("v.nii", nifti1(&|_| {}))],
        &["info", "v.nii"],
    ));
    // NIfTI-2 with impossible sizes.
    let nifti2 = |dim1: i64, offset: i64| {
        let mut h = vec![0u8; 544];
        h[0..4].copy_from_slice(&540i32.to_le_bytes());
        h[4..12].copy_from_slice(b"n+2\0\r\n\x1a\n");
        h[12..14].copy_from_slice(&4i16.to_le_bytes());
        for (i, d) in [3i64, dim1, 2, 2, 1, 1, 1, 1].iter().enumerate() {
            h[16 + 8 * i..24 + 8 * i].copy_from_slice(&d.to_le_bytes());
        }
        for i in 0..8 {
            h[104 + 8 * i..112 + 8 * i].copy_from_slice(&1f64.to_le_bytes());
        }
        h[168..176].copy_from_slice(&offset.to_le_bytes());
        h.extend([0u8; 64]);
        h
    };
    cases.push(info(
        "nifti2-dim-2^40",
        "v.nii",
        nifti2(1 << 40, 544),
        &["dim[1]"],
    ));
    cases.push(info(
        "nifti2-dim-negative",
        "v.nii",
        nifti2(-3, 544),
        &["dim[1]"],
    ));
    cases.push(info(
        "nifti2-offset-early",
        "v.nii",
        nifti2(2, 100),
        &["vox_offset"],
    ));
    cases.push(info(
        "nifti2-offset-negative",
        "v.nii",
        nifti2(2, -1),
        &["vox_offset"],
    ));
    cases.push(info(
        "nifti2-cut",
        "v.nii",
        nifti2(2, 544)[..300].to_vec(),
        &["540-byte"],
    ));
    cases.push(info(
        "nifti-gz-garbage",
        "v.nii.gz",
        [0x1f, 0x8b, 8, 0, 1, 2, 3].to_vec(),
        &[],
    ));
    cases
}

// ---- MetaImage, VTK, Analyze, .dat, DICOM --------------------------------------------------

fn meta(extra: &str, data_line: &str) -> Vec<u8> {
    format!(
        "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_SHORT\n{extra}ElementDataFile = {data_line}\n"
    )
    .into_bytes()
}

fn other_format_cases() -> Vec<Case> {
    let local = |extra: &str| {
        let mut bytes = meta(extra, "LOCAL");
        bytes.extend([0u8; 16]);
        bytes
    };
    let mut cases = Vec::new();
    // Each repeats a key the header already gives, which is refused.
    let mha: &[(&str, &str, &[&str])] = &[
        ("ndims-four", "NDims = 4\n", &["NDims"]),
        ("type-bad", "ElementType = MET_BOGUS\n", &["ElementType"]),
        (
            "spacing-nan",
            "ElementSpacing = 1 nan 1\n",
            &["ElementSpacing"],
        ),
        ("spacing-zero", "ElementSpacing = 1 0 1\n", &[]),
        (
            "spacing-four",
            "ElementSpacing = 1 1 1 1\n",
            &["ElementSpacing"],
        ),
        (
            "matrix-zero",
            "TransformMatrix = 0 0 0 0 1 0 0 0 1\n",
            &["TransformMatrix"],
        ),
        (
            "matrix-nan",
            "TransformMatrix = nan 0 0 0 1 0 0 0 1\n",
            &["TransformMatrix"],
        ),
        ("offset-nan", "Offset = nan 0 0\n", &["Offset"]),
        ("headersize-negative", "HeaderSize = -5\n", &["HeaderSize"]),
        ("compressed-garbage", "CompressedData = True\n", &[]),
        ("channels", "ElementNumberOfChannels = 3\n", &["channel"]),
        ("binary-false", "BinaryData = False\n", &["ASCII"]),
    ];
    for (name, extra, words) in mha {
        cases.push(info(&format!("mha-{name}"), "v.mha", local(extra), words));
    }
    let dims = |d: &str| {
        let mut b = format!(
            "ObjectType = Image\nNDims = 3\nDimSize = {d}\nElementType = MET_SHORT\nElementDataFile = LOCAL\n"
        )
        .into_bytes();
        b.extend([0u8; 16]);
        b
    };
    cases.push(info("mha-dims-zero", "v.mha", dims("2 0 2"), &["DimSize"]));
    cases.push(info(
        "mha-dims-wrap",
        "v.mha",
        dims("2147483648 2147483648 4"),
        &["grid"],
    ));
    cases.push(info("mha-dims-short", "v.mha", dims("2 2"), &["DimSize"]));
    cases.push(info(
        "mha-short-data",
        "v.mha",
        meta("", "LOCAL"),
        &["bytes"],
    ));
    cases.push(info(
        "mhd-missing",
        "v.mhd",
        meta("", "gone.raw"),
        &["gone.raw"],
    ));
    cases.push(info(
        "mhd-list-short",
        "v.mhd",
        meta("", "LIST\na.raw"),
        &["LIST"],
    ));
    cases.push(info(
        "mhd-pattern-huge",
        "v.mhd",
        meta("", "s%d.raw 0 4294967296 1"),
        &["pattern"],
    ));
    cases.push(info(
        "mhd-pattern-no-d",
        "v.mhd",
        meta("", "s%s.raw 1 2 1"),
        &["pattern"],
    ));
    cases.push(info(
        "mhd-device",
        "v.mhd",
        meta("", "/dev/zero"),
        &["zero"],
    ));
    // Legacy VTK.
    let legacy = |dims: &str, spacing: &str, kind: &str| {
        format!(
            "# vtk DataFile Version 3.0\nx\n{kind}\nDATASET STRUCTURED_POINTS\nDIMENSIONS {dims}\nSPACING {spacing}\nORIGIN 0 0 0\nPOINT_DATA 8\nSCALARS s unsigned_char 1\nLOOKUP_TABLE default\n"
        )
        .into_bytes()
        .into_iter()
        .chain([0u8; 8])
        .collect::<Vec<u8>>()
    };
    cases.push(info(
        "vtk-dims-zero",
        "v.vtk",
        legacy("0 2 2", "1 1 1", "BINARY"),
        &[],
    ));
    cases.push(info(
        "vtk-dims-wrap",
        "v.vtk",
        legacy("2147483648 2147483648 4", "1 1 1", "BINARY"),
        &[],
    ));
    cases.push(info(
        "vtk-spacing-nan",
        "v.vtk",
        legacy("2 2 2", "nan 1 1", "BINARY"),
        &[],
    ));
    cases.push(info(
        "vtk-ascii",
        "v.vtk",
        legacy("2 2 2", "1 1 1", "ASCII"),
        &["ASCII"],
    ));
    cases.push(info(
        "vtk-points-mismatch",
        "v.vtk",
        legacy("3 3 3", "1 1 1", "BINARY"),
        &[],
    ));
    cases.push(works(
        "vtk-good",
        vec![("v.vtk", legacy("2 2 2", "1 1 1", "BINARY"))],
        &["info", "v.vtk"],
    ));
    // VTK XML.
    let vti = |extent: &str, attrs: &str, array: &str| {
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt32\" {attrs}>\n<ImageData WholeExtent=\"{extent}\" Origin=\"0 0 0\" Spacing=\"1 1 1\">\n<Piece Extent=\"{extent}\">\n<PointData Scalars=\"s\">\n{array}\n</PointData>\n</Piece>\n</ImageData>\n</VTKFile>\n"
        )
        .into_bytes()
    };
    let ascii = "<DataArray type=\"UInt8\" Name=\"s\" format=\"ascii\">1 2 3 4 5 6 7 8</DataArray>";
    cases.push(works(
        "vti-ascii-good",
        vec![("v.vti", vti("0 1 0 1 0 1", "", ascii))],
        &["info", "v.vti"],
    ));
    cases.push(info(
        "vti-extent-reversed",
        "v.vti",
        vti("1 0 0 1 0 1", "", ascii),
        &[],
    ));
    cases.push(info(
        "vti-extent-huge",
        "v.vti",
        vti("0 2147483647 0 2147483647 0 3", "", ascii),
        &[],
    ));
    cases.push(info(
        "vti-ascii-word",
        "v.vti",
        vti("0 1 0 1 0 1", "", &ascii.replace(" 8<", " x<")),
        &["not a number"],
    ));
    cases.push(info(
        "vti-ascii-short",
        "v.vti",
        vti("0 1 0 1 0 1", "", &ascii.replace(" 7 8", "")),
        &["6 values"],
    ));
    cases.push(info(
        "vti-base64-bad",
        "v.vti",
        vti(
            "0 1 0 1 0 1",
            "",
            "<DataArray type=\"UInt8\" Name=\"s\" format=\"binary\">!!!!</DataArray>",
        ),
        &[],
    ));
    cases.push(info(
        "vti-lz4-claims-huge",
        "v.vti",
        vti(
            "0 1 0 1 0 1",
            "compressor=\"vtkLZ4DataCompressor\"",
            // One block said to inflate to 8 bytes from 4 bytes of garbage.
            "<DataArray type=\"UInt8\" Name=\"s\" format=\"binary\">AQAAAAgAAAAIAAAABAAAAA==AAAAAA==</DataArray>",
        ),
        &[],
    ));
    cases.push(info(
        "vti-not-imagedata",
        "v.vti",
        b"<VTKFile type=\"PolyData\"></VTKFile>".to_vec(),
        &["PolyData"],
    ));
    // Analyze 7.5.
    let analyze = |dim1: i16, datatype: i16| {
        let mut h = vec![0u8; 348];
        h[0..4].copy_from_slice(&348i32.to_le_bytes());
        for (i, d) in [3i16, dim1, 2, 2, 1, 1, 1, 1].iter().enumerate() {
            h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
        }
        h[70..72].copy_from_slice(&datatype.to_le_bytes());
        for i in 0..8 {
            h[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
        }
        h
    };
    cases.push(info("analyze-no-img", "v.hdr", analyze(2, 4), &["v.img"]));
    cases.push(case(
        "analyze-short-img",
        vec![("v.hdr", analyze(2, 4)), ("v.img", vec![0u8; 5])],
        &["info", "v.hdr"],
        &["v.img"],
    ));
    cases.push(case(
        "analyze-negative-dim",
        vec![("v.hdr", analyze(-2, 4)), ("v.img", vec![0u8; 16])],
        &["info", "v.hdr"],
        &["dim[1]"],
    ));
    cases.push(works(
        "analyze-good",
        vec![("v.hdr", analyze(2, 4)), ("v.img", vec![0u8; 16])],
        &["info", "v.hdr"],
    ));
    // Voreen .dat.
    let dat = |res: &str, thick: &str| {
        format!(
            "ObjectFileName: v.raw\nResolution: {res}\nSliceThickness: {thick}\nFormat: UCHAR\n"
        )
        .into_bytes()
    };
    cases.push(case(
        "dat-missing-raw",
        vec![("v.dat", dat("2 2 2", "1 1 1"))],
        &["info", "v.dat"],
        &["v.raw"],
    ));
    cases.push(case(
        "dat-resolution-zero",
        vec![("v.dat", dat("0 2 2", "1 1 1")), ("v.raw", vec![0u8; 8])],
        &["info", "v.dat"],
        &["grid [0, 2, 2]"],
    ));
    cases.push(case(
        "dat-thickness-nan",
        vec![("v.dat", dat("2 2 2", "nan 1 1")), ("v.raw", vec![0u8; 8])],
        &["info", "v.dat"],
        &["v.dat"],
    ));
    cases.push(case(
        "dat-short-raw",
        vec![("v.dat", dat("2 2 2", "1 1 1")), ("v.raw", vec![0u8; 3])],
        &["info", "v.dat"],
        &["v.raw"],
    ));
    // DICOM.
    let dicm = |tail: &[u8]| [&[0u8; 128][..], b"DICM", tail].concat();
    cases.push(info("dicom-garbage", "v.dcm", dicm(&[0xff; 40]), &[]));
    cases.push(info("dicom-magic-only", "v.dcm", dicm(&[]), &[]));
    cases.push(info(
        "dicom-meta-length-huge",
        "v.dcm",
        dicm(&[2, 0, 0, 0, b'U', b'L', 4, 0, 0xff, 0xff, 0xff, 0x7f]),
        &[],
    ));
    cases.push(case(
        "dicom-folder-of-garbage",
        vec![("a.dcm", dicm(&[1; 30])), ("b.dcm", dicm(&[2; 30]))],
        &["info", "{dir}"],
        &[],
    ));
    cases
}

// ---- Special files, scenes, meshes, arguments ----------------------------------------------

fn scene_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    let render = |scene: &'static str| -> Vec<&'static str> {
        vec!["render", scene, "--size", "32x32", "--out", "o.png"]
    };
    let bad: &[(&str, &str, &[&str])] = &[
        (
            "background-nan",
            "[output]\nbackground = [nan, 0, 0]",
            &["output.background"],
        ),
        (
            "background-inf",
            "[output]\nbackground = [inf, 0, 0]",
            &["output.background"],
        ),
        (
            "background-4",
            "[output]\nbackground = [0, 0, 0, 1]",
            &["background"],
        ),
        (
            "background-2",
            "[output]\nbackground = [0, 0]",
            &["background"],
        ),
        ("size-3", "[output]\nsize = [160, 120, 999]", &["size"]),
        ("size-zero", "[output]\nsize = [0, 120]", &["output.size"]),
        (
            "size-huge",
            "[output]\nsize = [16000, 16000]",
            &["output.size"],
        ),
        ("size-negative", "[output]\nsize = [-1, 120]", &["size"]),
        (
            "ordering-bad",
            "[output]\nordering = \"sideways\"",
            &["ordering"],
        ),
        (
            "view-from-zero",
            "[camera]\nview_from = [0, 0, 0]",
            &["view_from"],
        ),
        (
            "view-from-nan",
            "[camera]\nview_from = [nan, 0, 1]",
            &["view_from"],
        ),
        ("up-zero", "[camera]\nup = [0, 0, 0]", &["camera.up"]),
        ("eye-inf", "[camera]\neye = [inf, 0, 0]", &["camera.eye"]),
        ("fov-tiny", "[camera]\nfov = 1e-30", &["camera.fov"]),
        ("fov-nan", "[camera]\nfov = nan", &["camera.fov"]),
        ("fov-huge", "[camera]\nfov = 400", &["camera.fov"]),
        (
            "ortho-negative",
            "[camera]\northographic_height = -5",
            &["orthographic_height"],
        ),
        ("near-zero", "[camera]\nnear = 0", &["camera.near"]),
        (
            "view-unknown",
            "[camera]\nview = \"sideways\"",
            &["sideways"],
        ),
        (
            "headlight-nan",
            "[lights]\nheadlight = nan",
            &["lights.headlight"],
        ),
        (
            "ambient-negative",
            "[lights]\nambient = -1",
            &["lights.ambient"],
        ),
        (
            "light-direction-zero",
            "[[lights.directional]]\ndirection = [0, 0, 0]\ncolor = [1, 1, 1]",
            &["direction"],
        ),
        (
            "light-color-nan",
            "[[lights.directional]]\ndirection = [0, 0, 1]\ncolor = [nan, 1, 1]",
            &["color"],
        ),
        (
            "lights-five",
            &"[[lights.directional]]\ndirection = [0, 0, 1]\ncolor = [1, 1, 1]\n".repeat(5),
            &["lights.directional", "4"],
        ),
        ("unknown-key", "bogus = 1", &["bogus"]),
        ("unknown-table", "[bogus]\nx = 1", &["bogus"]),
    ];
    let volume = |extra: &str| format!("[[volume]]\npath = \"builtin:shoulder-phantom\"\n{extra}");
    let bad_volume: &[(&str, &str, &[&str])] = &[
        ("shift-nan", "shift = nan", &["shift"]),
        ("shift-inf", "shift = inf", &["shift"]),
        (
            "level-width-negative",
            "level_width = [100, -5]",
            &["level_width"],
        ),
        (
            "level-width-nan",
            "level_width = [nan, 5]",
            &["level_width"],
        ),
        ("shading-two", "shading = 2", &["shading"]),
        ("shell-nan", "shell = nan", &["shell"]),
        (
            "min-opacity-negative",
            "min_opacity = -0.5",
            &["min_opacity"],
        ),
        (
            "opacity-reference-zero",
            "opacity_reference_mm = 0",
            &["opacity_reference_mm"],
        ),
        (
            "window-reversed",
            "transfer = \"ramp\"\nwindow = [100, 50]",
            &["window"],
        ),
        (
            "color-with-preset",
            "transfer = \"ct-bone\"\ncolor = [1, 0, 0, 1]",
            &["color"],
        ),
        (
            "color-five",
            "transfer = \"ramp\"\nwindow = [0, 1]\ncolor = [1, 0, 0, 1, 1]",
            &["color"],
        ),
        ("spacing-on-builtin", "spacing = [1, 1, 1]", &["spacing"]),
        ("frame-on-builtin", "frame = 1", &["frame"]),
        ("transfer-unknown", "transfer = \"rainbow\"", &["rainbow"]),
        (
            "translate-nan",
            "transform = { translate = [nan, 0, 0] }",
            &["translate"],
        ),
        (
            "scale-zero",
            "transform = { scale = [0, 1, 1] }",
            &["scale"],
        ),
        (
            "matrix-nan",
            "transform = { matrix = [nan,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1] }",
            &["matrix"],
        ),
        (
            "matrix-singular",
            "transform = { matrix = [0,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1] }",
            &["transform"],
        ),
        (
            "matrix-and-scale",
            "transform = { scale = [1, 1, 1], matrix = [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1] }",
            &["matrix"],
        ),
        (
            "crop-reversed",
            "crop_box = { min = [10, 0, 0], max = [0, 10, 10] }",
            &["crop"],
        ),
        (
            "cut-away-negative",
            "cut_away_anterior_humerus = -3",
            &["cut_away_anterior_humerus"],
        ),
    ];
    let mesh = |extra: &str| format!("[[mesh]]\npath = \"builtin:prosthesis\"\n{extra}");
    let bad_mesh: &[(&str, &str, &[&str])] = &[
        ("color-nan", "color = [nan, 0, 0]", &["color"]),
        ("color-two", "color = [1, 0]", &["color"]),
        ("color-high", "color = [2, 0, 0]", &["color"]),
        ("opacity-two", "opacity = 2", &["opacity"]),
        ("roughness-nan", "roughness = nan", &["roughness"]),
        ("units-bad", "units = \"furlong\"", &["furlong"]),
        ("frame-bad", "frame = \"XYZ\"", &["XYZ"]),
        ("seat-unknown", "seat = \"nowhere\"", &["nowhere"]),
        ("missing-file", "path = \"gone.stl\"", &["gone.stl"]),
        (
            "rotate-inf",
            "transform = { rotate_degrees = [inf, 0, 0] }",
            &["rotate_degrees"],
        ),
    ];
    for (name, text, words) in bad {
        cases.push(case(
            &format!("scene-{name}"),
            vec![("s.toml", text.as_bytes().to_vec())],
            &render("s.toml"),
            words,
        ));
    }
    for (name, extra, words) in bad_volume {
        cases.push(case(
            &format!("scene-volume-{name}"),
            vec![("s.toml", volume(extra).into_bytes())],
            &render("s.toml"),
            words,
        ));
    }
    for (name, extra, words) in bad_mesh {
        let text = if extra.starts_with("path") {
            format!("[[mesh]]\n{extra}\n")
        } else {
            mesh(extra)
        };
        cases.push(case(
            &format!("scene-mesh-{name}"),
            vec![("s.toml", text.into_bytes())],
            &render("s.toml"),
            words,
        ));
    }
    cases.push(works(
        "scene-good",
        vec![("s.toml", volume("shift = 100").into_bytes())],
        &render("s.toml"),
    ));
    cases.push(case(
        "scene-binary",
        vec![("s.toml", vec![0xff, 0xfe, 0, 1, 2])],
        &render("s.toml"),
        &["s.toml"],
    ));
    cases
}

fn mesh_cases() -> Vec<Case> {
    let render = |mesh: &'static str| -> Vec<&'static str> {
        vec![
            "render", "--mesh", mesh, "--size", "32x32", "--out", "o.png",
        ]
    };
    let gltf = |uri: &str, length: usize| {
        format!(
            "{{\"asset\":{{\"version\":\"2.0\"}},\"buffers\":[{{\"uri\":\"{uri}\",\"byteLength\":{length}}}],\"bufferViews\":[{{\"buffer\":0,\"byteLength\":36}}],\"accessors\":[{{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,1,0]}}],\"meshes\":[{{\"primitives\":[{{\"attributes\":{{\"POSITION\":0}}}}]}}],\"nodes\":[{{\"mesh\":0}}],\"scenes\":[{{\"nodes\":[0]}}]}}"
        )
        .into_bytes()
    };
    let triangle: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let mut cases = vec![
        case(
            "gltf-absolute",
            vec![("m.gltf", gltf("/etc/passwd", 36))],
            &render("m.gltf"),
            &["/etc/passwd"],
        ),
        case(
            "gltf-encoded-absolute",
            vec![("m.gltf", gltf("%2Fetc%2Fpasswd", 36))],
            &render("m.gltf"),
            &["/etc/passwd"],
        ),
        case(
            "gltf-encoded-parent",
            vec![("m.gltf", gltf("..%2F..%2Fetc%2Fpasswd", 36))],
            &render("m.gltf"),
            &["outside"],
        ),
        case(
            "gltf-parent",
            vec![("m.gltf", gltf("../b.bin", 36))],
            &render("m.gltf"),
            &["outside"],
        ),
        case(
            "gltf-scheme",
            vec![("m.gltf", gltf("http://example.com/b.bin", 36))],
            &render("m.gltf"),
            &["http"],
        ),
        case(
            "gltf-bad-escape",
            vec![("m.gltf", gltf("b%zz.bin", 36))],
            &render("m.gltf"),
            &["percent"],
        ),
        case(
            "gltf-missing-buffer",
            vec![("m.gltf", gltf("gone.bin", 36))],
            &render("m.gltf"),
            &["gone.bin"],
        ),
        case(
            "gltf-short-buffer",
            vec![("m.gltf", gltf("b.bin", 36)), ("b.bin", vec![0u8; 12])],
            &render("m.gltf"),
            &["m.gltf"],
        ),
        case(
            "gltf-device-buffer",
            vec![("m.gltf", gltf("zero", 36))],
            &render("m.gltf"),
            &["zero"],
        ),
        case(
            "gltf-data-uri-bad",
            vec![(
                "m.gltf",
                gltf("data:application/octet-stream;base64,@@@@", 36),
            )],
            &render("m.gltf"),
            &["data URI"],
        ),
        case(
            "gltf-not-json",
            vec![("m.gltf", b"{ not json".to_vec())],
            &render("m.gltf"),
            &["m.gltf"],
        ),
        works(
            "gltf-good",
            vec![("m.gltf", gltf("b.bin", 36)), ("b.bin", triangle.clone())],
            &render("m.gltf"),
        ),
        works(
            "gltf-encoded-good",
            vec![
                ("m.gltf", gltf("b%20c.bin", 36)),
                ("b c.bin", triangle.clone()),
            ],
            &render("m.gltf"),
        ),
    ];
    // STL: a binary header declaring a billion triangles, and NaN vertices.
    let mut stl = vec![0u8; 80];
    stl.extend(1_000_000_000u32.to_le_bytes());
    stl.extend([0u8; 50]);
    cases.push(case(
        "stl-count-huge",
        vec![("m.stl", stl)],
        &render("m.stl"),
        &["m.stl"],
    ));
    let mut nan = vec![0u8; 80];
    nan.extend(1u32.to_le_bytes());
    nan.extend([0u8; 12]);
    nan.extend(f32::NAN.to_le_bytes());
    nan.extend([0u8; 34]);
    cases.push(case(
        "stl-nan",
        vec![("m.stl", nan)],
        &render("m.stl"),
        &["m.stl"],
    ));
    cases.push(case(
        "stl-ascii-garbage",
        vec![("m.stl", b"solid x\nfacet normal a b c\n".to_vec())],
        &render("m.stl"),
        &["m.stl"],
    ));
    // OBJ.
    cases.push(case(
        "obj-face-out-of-range",
        vec![("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n".to_vec())],
        &render("m.obj"),
        &["m.obj"],
    ));
    cases.push(case(
        "obj-nan-vertex",
        vec![("m.obj", b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec())],
        &render("m.obj"),
        &["m.obj"],
    ));
    // A mesh file without triangles is a warning; the rest of the scene is drawn.
    cases.push(works(
        "obj-no-faces",
        vec![("m.obj", b"v 0 0 0\n".to_vec())],
        &render("m.obj"),
    ));
    // A material library outside the folder is left out with a warning; the mesh still draws.
    cases.push(works(
        "obj-mtllib-outside",
        vec![(
            "m.obj",
            b"mtllib ../../../etc/passwd\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec(),
        )],
        &render("m.obj"),
    ));
    cases.push(case(
        "mesh-unknown-format",
        vec![("m.xyz", b"hello".to_vec())],
        &render("m.xyz"),
        &["m.xyz"],
    ));
    cases
}

fn special_file_cases() -> Vec<Case> {
    vec![
        case(
            "device-volume",
            vec![],
            &["info", "/dev/zero"],
            &["/dev/zero", "character device"],
        ),
        case(
            "device-mesh",
            vec![],
            &["render", "--mesh", "/dev/zero", "--out", "o.png"],
            &["/dev/zero", "character device"],
        ),
        case(
            "device-scene",
            vec![],
            &["render", "/dev/null", "--out", "o.png"],
            &["/dev/null"],
        ),
        case(
            "folder-mesh",
            vec![("sub/x", vec![1])],
            &["render", "--mesh", "sub", "--out", "o.png"],
            &["sub"],
        ),
        case(
            "missing-volume",
            vec![],
            &["info", "nothing.nrrd"],
            &["nothing.nrrd"],
        ),
        case(
            "missing-scene",
            vec![],
            &["render", "nothing.toml", "--out", "o.png"],
            &["nothing.toml"],
        ),
        case(
            "empty-volume",
            vec![("e.nrrd", vec![])],
            &["info", "e.nrrd"],
            &["e.nrrd"],
        ),
        case(
            "empty-manifest",
            vec![("m.toml", vec![])],
            &["batch", "m.toml", "--check"],
            &["m.toml"],
        ),
    ]
}

fn argument_cases() -> Vec<Case> {
    let render = |extra: &[&'static str]| -> Vec<&'static str> {
        let mut args = vec!["render", "--out", "o.png"];
        args.extend(extra);
        args
    };
    vec![
        case("size-zero", vec![], &render(&["--size", "0x0"]), &["size"]),
        case(
            "size-huge",
            vec![],
            &render(&["--size", "100000x100000"]),
            &["size"],
        ),
        case("size-word", vec![], &render(&["--size", "big"]), &["size"]),
        case(
            "window-reversed",
            vec![],
            &render(&["--window", "5,1"]),
            &["--window"],
        ),
        case(
            "window-nan",
            vec![],
            &render(&["--window", "nan,1"]),
            &["window"],
        ),
        case(
            "shift-inf",
            vec![],
            &render(&["--shift", "inf"]),
            &["shift"],
        ),
        case(
            "orthographic-negative",
            vec![],
            &render(&["--orthographic", "-5"]),
            &["orthographic"],
        ),
        case(
            "nifti-transform-bad",
            vec![],
            &["info", "--nifti-transform", "best", "x.nii"],
            &["best"],
        ),
        case(
            "order-dims-wrap",
            vec![],
            &[
                "order",
                "--dims",
                "2147483648,2147483648,4",
                "--eye",
                "1,1,1",
                "--ordering",
                "btf",
                "--out",
                "o.bin",
            ],
            &["grid"],
        ),
        case(
            "order-dims-zero",
            vec![],
            &[
                "order",
                "--dims",
                "0,4,4",
                "--eye",
                "1,1,1",
                "--ordering",
                "btf",
                "--out",
                "o.bin",
            ],
            &["axis without voxels"],
        ),
        case(
            "order-spacing-zero",
            vec![],
            &[
                "order",
                "--dims",
                "4,4,4",
                "--spacing",
                "0,1,1",
                "--eye",
                "1,1,1",
                "--ordering",
                "btf",
                "--out",
                "o.bin",
            ],
            &["spacing"],
        ),
        case(
            "order-eye-nan",
            vec![],
            &[
                "order",
                "--dims",
                "4,4,4",
                "--eye",
                "nan,1,1",
                "--ordering",
                "btf",
                "--out",
                "o.bin",
            ],
            &["eye"],
        ),
        case(
            "raw-dims-without-scalar",
            vec![("v.raw", vec![0u8; 8])],
            &["render", "v.raw", "--dims", "2,2,2", "--out", "o.png"],
            &["scalar"],
        ),
        case(
            "raw-short",
            vec![("v.raw", vec![0u8; 7])],
            &[
                "render", "v.raw", "--dims", "2,2,2", "--scalar", "u8", "--out", "o.png",
            ],
            &["v.raw"],
        ),
    ]
}

/// Pieces of Rust debug formatting that a message for people never holds.
const DEBUG_TEXT: &[&str] = &[
    "Some(", "None)", "DVec3(", "Vec3(", "Spec {", "Error {", "Os {", "kind: ",
];

/// The `splatscene` binary, run in `dir` under the time and memory limits.
fn run(dir: &Path, args: &[String]) -> (Option<i32>, String, Duration) {
    let start = Instant::now();
    let command = format!(
        "ulimit -v {}; exec timeout -s KILL 10 \"$0\" \"$@\"",
        8 * 1024 * 1024
    );
    let output = Command::new("sh")
        .arg("-c")
        .arg(command)
        .arg(env!("CARGO_BIN_EXE_splatscene"))
        .args(args)
        .current_dir(dir)
        .env("NODEVICE_SELECT", "1")
        .env("RUST_BACKTRACE", "0")
        .env("SPLATSCENE_MEMORY_LIMIT", "256M")
        .output()
        .expect("run splatscene");
    let text = String::from_utf8_lossy(&output.stderr).into_owned();
    (output.status.code(), text, start.elapsed())
}

fn all_cases() -> Vec<Case> {
    [
        nrrd_cases(),
        nifti_cases(),
        other_format_cases(),
        scene_cases(),
        mesh_cases(),
        special_file_cases(),
        argument_cases(),
        limit_cases(),
        output_cases(),
        input_output_cases(),
    ]
    .into_iter()
    .flatten()
    .collect()
}

#[test]
fn crafted_inputs_end_in_clear_errors_or_correct_results() {
    let cases = all_cases();
    assert!(cases.len() >= 150, "only {} cases", cases.len());
    let root = common::scratch("adversarial");
    let mut failures = Vec::new();
    let mut slowest = (Duration::ZERO, "");
    for case in &cases {
        let dir: PathBuf = root.join(&case.name);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, bytes) in &case.files {
            let path = dir.join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, bytes).unwrap();
        }
        if let Some(setup) = case.setup {
            setup(&dir);
        }
        // A device file and a named pipe for inputs to name.
        if !dir.join("zero").exists() {
            std::os::unix::fs::symlink("/dev/zero", dir.join("zero")).ok();
        }
        if !dir.join("fifo").exists() {
            let made = Command::new("mkfifo").arg(dir.join("fifo")).status();
            assert!(made.is_ok_and(|s| s.success()), "mkfifo failed");
        }
        let args: Vec<String> = case
            .args
            .iter()
            .map(|a| a.replace("{dir}", dir.to_str().unwrap()))
            .collect();
        let (code, stderr, took) = run(&dir, &args);
        if took > slowest.0 {
            slowest = (took, &case.name);
        }
        let problem = match (&case.expect, code) {
            (_, None) | (_, Some(137)) => {
                Some(format!("killed after {took:?} (time or memory limit)"))
            }
            (_, _) if stderr.contains("panicked") => Some("panicked".into()),
            (Expect::Ok, Some(0)) => None,
            (Expect::Ok, Some(c)) => Some(format!("exit {c}, expected success")),
            (Expect::Error(_), Some(0)) => Some("succeeded, expected an error".into()),
            (Expect::Error(words), Some(_)) => {
                let missing: Vec<&String> = words
                    .iter()
                    .filter(|w| !stderr.contains(w.as_str()))
                    .collect();
                (!missing.is_empty() || !stderr.to_lowercase().contains("error"))
                    .then(|| format!("message lacks {missing:?}"))
            }
        };
        // Rust's debug text is not for people.
        let debug = DEBUG_TEXT.iter().find(|d| stderr.contains(*d));
        let problem = problem
            .or_else(|| debug.map(|d| format!("debug text {d:?} in the message")))
            .or_else(|| case.after.and_then(|check| check(&dir).err()));
        if let Some(problem) = problem {
            failures.push(format!(
                "{}: {problem}\n    {}",
                case.name,
                stderr.trim().replace('\n', "\n    ")
            ));
        }
    }
    eprintln!(
        "{} cases; the slowest, {}, took {:?}",
        cases.len(),
        slowest.1,
        slowest.0
    );
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

// ---- Sizes against the memory budget, special data files, values, outputs -----------------

/// `bytes` compressed with gzip (fast: the cases below compress runs of zeros).
fn gzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}

/// A NIfTI-1 header (and the 4 bytes after it) for a `dims` grid of u8.
fn nifti_header_u8(dims: [i16; 3]) -> Vec<u8> {
    nifti1(&|h| {
        h.truncate(352);
        for (i, d) in dims.iter().enumerate() {
            put_i16(h, 42 + 2 * i, *d);
        }
        put_i16(h, 70, 2);
        put_i16(h, 72, 8);
    })
}

fn limit_cases() -> Vec<Case> {
    // A real bomb: 1.2 MB of gzip that inflates to the 256 MiB of a 1024x1024x256 grid,
    // which drawing would take 512 MiB for (its byte and one more a voxel), past the 256 MiB
    // budget: refused from the header.
    let grid = 1024 * 1024 * 256;
    let mut bomb = nifti_header_u8([1024, 1024, 256]);
    bomb.extend(std::iter::repeat_n(0u8, grid));
    let bomb = gzip(&bomb);
    assert!(bomb.len() < 2 << 20, "the bomb is {} bytes", bomb.len());
    // A stream that inflates to far more than its header declares.
    let mut long = nifti_header_u8([2, 2, 2]);
    long.extend(std::iter::repeat_n(0u8, 64 << 20));
    let long = gzip(&long);
    let nrrd_bomb = nrrd(
        &[
            ("type", "uchar"),
            ("sizes", "1024 1024 256"),
            ("encoding", "gzip"),
        ],
        &gzip(&vec![0u8; grid]),
    );
    let bz2_bomb = {
        use std::io::Write;
        let mut e = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::fast());
        e.write_all(&[0u8; 1 << 20]).unwrap();
        nrrd(
            &[
                ("type", "uchar"),
                ("sizes", "1024 1024 256"),
                ("encoding", "bzip2"),
            ],
            &e.finish().unwrap(),
        )
    };
    let mha_bomb = {
        let mut b = b"ObjectType = Image\nNDims = 3\nDimSize = 1024 1024 256\nElementType = MET_UCHAR\nCompressedData = True\nElementDataFile = LOCAL\n".to_vec();
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut z, &[0u8; 1 << 20]).unwrap();
        b.extend(z.finish().unwrap());
        b
    };
    // A deflated DICOM data set of 128 MiB of zeros in a file of some 128 KiB (1000 times
    // smaller): dicom-rs would inflate it whole; it is refused while counting.
    let deflated_bomb = {
        use std::io::Write;
        let uid = b"1.2.840.10008.1.2.1.99";
        let mut b = vec![0u8; 128];
        b.extend(b"DICM");
        b.extend([2, 0, 0, 0, b'U', b'L', 4, 0]);
        b.extend((8 + uid.len() as u32).to_le_bytes());
        b.extend([2, 0, 0x10, 0, b'U', b'I']);
        b.extend((uid.len() as u16).to_le_bytes());
        b.extend(uid);
        let mut e = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
        e.write_all(&vec![0u8; 128 << 20]).unwrap();
        b.extend(e.finish().unwrap());
        b
    };
    let budget = ["memory", "SPLATSCENE_MEMORY_LIMIT"];
    let words = |file: &'static str| -> Vec<&'static str> {
        let mut w = vec![file];
        w.extend(budget);
        w
    };
    let outside_gltf = b"{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"uri\":\"../buf.bin\",\"byteLength\":36}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,1,0]}],\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]}".to_vec();
    let triangle: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let stl_far = b"solid far\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1e38 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid far\n".to_vec();
    let obj_far = b"v 0 0 0\nv 1 0 0\nv 0 -3e37 0\nf 1 2 3\n".to_vec();
    let render_mesh = |mesh: &'static str| -> Vec<&'static str> {
        vec![
            "render", "--mesh", mesh, "--size", "32x32", "--out", "o.png",
        ]
    };
    vec![
        case("nii-gz-bomb", vec![("b.nii.gz", bomb)], &["info", "b.nii.gz"], &words("b.nii.gz")),
        case(
            "nii-gz-inflates-past-its-header",
            vec![("l.nii.gz", long)],
            &["info", "l.nii.gz"],
            &["l.nii.gz"],
        ),
        case("nrrd-gzip-bomb", vec![("b.nrrd", nrrd_bomb)], &["info", "b.nrrd"], &words("b.nrrd")),
        case("nrrd-bzip2-bomb", vec![("b.nrrd", bz2_bomb)], &["info", "b.nrrd"], &words("b.nrrd")),
        case("mha-zlib-bomb", vec![("b.mha", mha_bomb)], &["info", "b.mha"], &words("b.mha")),
        case(
            "dicom-deflate-bomb",
            vec![("d.dcm", deflated_bomb)],
            &["info", "d.dcm"],
            &["d.dcm", "inflates to more than"],
        ),
        case(
            "nrrd-pattern-billions",
            vec![(
                "p.nhdr",
                nrrd(
                    &[
                        ("type", "uchar"),
                        ("sizes", "1 1 4294967295"),
                        ("data file", "s%d.raw 1 4294967295 1"),
                    ],
                    &[],
                ),
            )],
            &["info", "p.nhdr"],
            &["p.nhdr"],
        ),
        case(
            "raw-over-budget",
            vec![("v.raw", vec![0u8; 8])],
            &[
                "render", "v.raw", "--dims", "2048,2048,1024", "--scalar", "u8", "--out", "o.png",
            ],
            &words("v.raw"),
        ),
        case("fifo-volume", vec![], &["info", "fifo"], &["fifo", "named pipe"]),
        case(
            "fifo-scene",
            vec![],
            &["render", "fifo", "--out", "o.png"],
            &["fifo", "named pipe"],
        ),
        case("fifo-mesh", vec![], &render_mesh("fifo"), &["fifo", "named pipe"]),
        case(
            "fifo-nrrd-data-file",
            vec![("f.nhdr", nrrd(&[("data file", "fifo")], &[]))],
            &["info", "f.nhdr"],
            &["f.nhdr", "fifo", "named pipe"],
        ),
        case(
            "device-nrrd-data-file",
            vec![("z.nhdr", nrrd(&[("data file", "zero")], &[]))],
            &["info", "z.nhdr"],
            &["z.nhdr", "character device"],
        ),
        case(
            "fifo-mha-data-file",
            vec![("f.mhd", meta("", "fifo"))],
            &["info", "f.mhd"],
            &["f.mhd", "fifo", "named pipe"],
        ),
        case(
            "fifo-gltf-buffer",
            vec![(
                "m.gltf",
                b"{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"uri\":\"fifo\",\"byteLength\":36}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,1,0]}],\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]}".to_vec(),
            )],
            &render_mesh("m.gltf"),
            &["fifo", "named pipe"],
        ),
        // A material library that cannot be read leaves default materials, with a warning.
        works(
            "fifo-obj-mtllib",
            vec![("m.obj", b"mtllib fifo\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec())],
            &render_mesh("m.obj"),
        ),
        // The same buffer outside the glTF's folder: refused, and drawn when allowed.
        case(
            "gltf-outside-refused",
            vec![
                ("sub/m.gltf", outside_gltf.clone()),
                ("buf.bin", triangle.clone()),
            ],
            &render_mesh("sub/m.gltf"),
            &["outside", "--allow-outside-paths"],
        ),
        works(
            "gltf-outside-allowed",
            vec![("sub/m.gltf", outside_gltf), ("buf.bin", triangle)],
            &[
                "render",
                "--mesh",
                "sub/m.gltf",
                "--allow-outside-paths",
                "--size",
                "32x32",
                "--out",
                "o.png",
            ],
        ),
        case("stl-far-coordinate", vec![("far.stl", stl_far)], &render_mesh("far.stl"), &["far.stl", "coordinate"]),
        case("obj-far-coordinate", vec![("far.obj", obj_far)], &render_mesh("far.obj"), &["far.obj", "coordinate"]),
        case(
            "measure-far-point",
            vec![],
            &["measure", "--point", "1e300,0,0", "--point", "0,0,0"],
            &["point", "from the origin"],
        ),
        case(
            "orderings-no-views",
            vec![],
            &["orderings", "--orbit-views", "0", "--fly-in-views", "0", "--out-dir", "r"],
            &["--orbit-views", "--fly-in-views"],
        ),
        case("fov-tiny", vec![], &["render", "--fov", "1e-30", "--out", "o.png"], &["--fov"]),
        case(
            "fov-with-orthographic",
            vec![],
            &["render", "--fov", "30", "--orthographic", "200", "--out", "o.png"],
            &["--fov", "--orthographic"],
        ),
        case(
            "spacings-inf-shown",
            vec![("s.nrrd", nrrd(&[("spacings", "1 inf 1")], &[0u8; 16]))],
            &["info", "s.nrrd"],
            &["s.nrrd", "inf"],
        ),
        case(
            "manifest-size-three",
            vec![("m.toml", b"[[job]]\nname = \"a\"\nsizes = [[64, 64, 3]]\n".to_vec())],
            &["batch", "m.toml", "--check"],
            &["m.toml", "sizes", "3 values"],
        ),
    ]
}

/// The case's folder holds `keep.txt` and `.o.png.partial` as they were written, and no
/// temporary of the tool's.
fn files_kept(dir: &Path) -> Result<(), String> {
    for (name, bytes) in [
        ("keep.txt", &b"mine"[..]),
        (".o.png.partial", &b"also mine"[..]),
    ] {
        match std::fs::read(dir.join(name)) {
            Ok(b) if b == bytes => {}
            _ => return Err(format!("{name} was changed or removed")),
        }
    }
    let mut names = Vec::new();
    for entry in walk(dir) {
        let name = entry.file_name().unwrap().to_string_lossy().into_owned();
        if name.ends_with(".partial") && name != ".o.png.partial" {
            names.push(name);
        }
    }
    match names.is_empty() {
        true => Ok(()),
        false => Err(format!("temporaries left behind: {names:?}")),
    }
}

/// Every file below `dir`.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            out.extend(walk(&path));
        } else {
            out.push(path);
        }
    }
    out
}

fn output_cases() -> Vec<Case> {
    let mine = || {
        vec![
            ("keep.txt", b"mine".to_vec()),
            (".o.png.partial", b"also mine".to_vec()),
            ("sub/keep.txt", b"mine".to_vec()),
        ]
    };
    let with_check = |mut c: Case| {
        c.after = Some(files_kept);
        c
    };
    let small = |out: &'static str| -> Vec<&'static str> {
        vec!["render", "--size", "32x24", "--out", out]
    };
    vec![
        // The named output is written; a user's file at the old fixed temporary name is not.
        with_check(Case {
            expect: Expect::Ok,
            ..case("out-beside-a-partial-file", mine(), &small("o.png"), &[])
        }),
        with_check(case("out-is-a-folder", mine(), &small("sub"), &["sub"])),
        with_check(case(
            "out-in-a-missing-folder",
            mine(),
            &small("gone/o.png"),
            &["gone"],
        )),
        with_check(case(
            "out-is-a-fifo-without-reader",
            mine(),
            &small("fifo"),
            &["fifo", "no process is reading"],
        )),
        with_check(case(
            "depth-is-out",
            mine(),
            &[
                "render", "--size", "32x24", "--out", "o.png", "--depth", "./o.png",
            ],
            &["o.png"],
        )),
    ]
}

// ---- Outputs against inputs, links, sidecars, shard counts, silent choices ------------------

/// A 4x4x4 `uchar` NRRD: the input every case below must leave as it was.
fn ct_nrrd() -> Vec<u8> {
    let mut bytes =
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nencoding: raw\n\n".to_vec();
    bytes.extend((0..64u8).map(|v| v * 4));
    bytes
}

/// `ct.nrrd`, `ct.raw` (as written for the detached header) and `keep.txt` are as written.
fn inputs_kept(dir: &Path) -> Result<(), String> {
    let raw: Vec<u8> = (0..64u8).map(|v| v * 4).collect();
    for (name, bytes) in [
        ("ct.nrrd", ct_nrrd()),
        ("ct.raw", raw),
        ("keep.txt", b"mine".to_vec()),
    ] {
        match std::fs::read(dir.join(name)) {
            Ok(b) if b == bytes => {}
            Ok(_) => return Err(format!("{name} was changed")),
            Err(e) => return Err(format!("{name}: {e}")),
        }
    }
    Ok(())
}

fn input_output_cases() -> Vec<Case> {
    let files = || -> Vec<(&'static str, Vec<u8>)> {
        vec![
            ("ct.nrrd", ct_nrrd()),
            ("ct.raw", (0..64u8).map(|v| v * 4).collect()),
            (
                "ct.nhdr",
                b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nencoding: raw\ndata file: ct.raw\n".to_vec(),
            ),
            ("keep.txt", b"mine".to_vec()),
        ]
    };
    let with = |mut c: Case, setup: Option<fn(&Path)>| {
        c.after = Some(inputs_kept);
        c.setup = setup.or(c.setup);
        c
    };
    let render = |out: &[&'static str]| -> Vec<&'static str> {
        let mut args = vec!["render", "ct.nrrd", "--size", "32x24"];
        args.extend(out);
        args
    };
    let scene = |extra: &str| -> Vec<u8> {
        format!("[[volume]]\npath = \"ct.nrrd\"\n{extra}").into_bytes()
    };
    let files_and = |name: &'static str, bytes: Vec<u8>| {
        let mut f = files();
        f.push((name, bytes));
        f
    };
    let manifest = |extra: &str| -> Vec<u8> {
        format!("[[job]]\nname = \"a\"\nvolume = \"ct.nrrd\"\nviews = [\"anterior\"]\nsizes = [[32, 24]]\n{extra}").into_bytes()
    };
    vec![
        with(case("out-is-the-volume", files(), &render(&["--out", "ct.nrrd"]), &["ct.nrrd", "input"]), None),
        with(case("out-is-the-volume-by-another-name", files(), &render(&["--out", "./sub/../ct.nrrd"]), &["ct.nrrd", "input"]), Some(|d| std::fs::create_dir_all(d.join("sub")).unwrap())),
        with(case("depth-is-the-volume", files(), &render(&["--out", "o.png", "--depth", "ct.nrrd"]), &["ct.nrrd", "input"]), None),
        with(
            case("out-links-to-the-volume", files(), &render(&["--out", "link.png"]), &["link.png", "input", "ct.nrrd"]),
            Some(|d| std::os::unix::fs::symlink("ct.nrrd", d.join("link.png")).unwrap()),
        ),
        with(
            case("out-links-through-two-links", files(), &render(&["--out", "l2.png"]), &["l2.png", "input"]),
            Some(|d| {
                std::os::unix::fs::symlink("ct.nrrd", d.join("l1.png")).unwrap();
                std::os::unix::fs::symlink(d.join("l1.png"), d.join("l2.png")).unwrap();
            }),
        ),
        with(
            case("out-is-a-hard-link-to-the-volume", files(), &render(&["--out", "hard.png"]), &["hard.png", "input"]),
            Some(|d| std::fs::hard_link(d.join("ct.nrrd"), d.join("hard.png")).unwrap()),
        ),
        with(
            case("out-is-a-detached-data-file", files(), &["render", "ct.nhdr", "--size", "32x24", "--out", "ct.raw"], &["ct.raw", "input"]),
            None,
        ),
        with(
            case("depth-sidecar-is-the-out", files(), &render(&["--out", "a.json", "--depth", "a.png"]), &["a.json", "calibration"]),
            None,
        ),
        with(
            case("depth-is-its-own-sidecar", files(), &render(&["--out", "o.png", "--depth", "d.json"]), &["d.json", ".png"]),
            None,
        ),
        with(
            case("depth-sidecar-is-the-volume", files_and("v.json", ct_nrrd()), &["render", "v.json", "--size", "32x24", "--out", "o.png", "--depth", "v.png"], &["v.json", "input"]),
            None,
        ),
        with(
            case("measure-out-is-the-scene", files_and("s.toml", scene("")), &["measure", "s.toml", "--point", "0,0,0", "--point", "1,0,0", "--out", "s.toml"], &["s.toml", "input"]),
            None,
        ),
        with(
            case("measure-out-is-the-volume", files(), &["measure", "ct.nrrd", "--point", "0,0,0", "--point", "1,0,0", "--out", "ct.nrrd"], &["ct.nrrd", "input"]),
            None,
        ),
        with(
            case("nrrd-data-file-is-the-header", files_and("self.nhdr", b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: self.nhdr\n".to_vec()), &["info", "self.nhdr"], &["self.nhdr", "header itself"]),
            None,
        ),
        with(
            case("dat-object-file-is-the-header", files_and("v.dat", b"ObjectFileName: v.dat\nResolution: 2 2 2\nSliceThickness: 1 1 1\nFormat: UCHAR\n".to_vec()), &["info", "v.dat"], &["v.dat", "header itself"]),
            None,
        ),
        with(
            case("nrrd-short-data-file-names-the-header", files_and("short.nhdr", b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: raw\ndata file: ct.raw\n".to_vec()), &["info", "short.nhdr"], &["short.nhdr", "ct.raw", "512"]),
            None,
        ),
        with(
            case("matrix-projective", files_and("s.toml", scene("transform = { matrix = [1,0,0,0.5, 0,1,0,0, 0,0,1,0, 0,0,0,1] }")), &["render", "s.toml", "--size", "32x24", "--out", "o.png"], &["matrix", "last row"]),
            None,
        ),
        with(
            case("crop-box-outside", files_and("s.toml", scene("crop_box = { min = [100, 100, 100], max = [200, 200, 200] }")), &["render", "s.toml", "--size", "32x24", "--out", "o.png"], &["crop_box", "outside"]),
            None,
        ),
        with(
            case(
                "measurement-node-names-two-meshes",
                files_and("s.toml", scene("[[mesh]]\nname = \"stem\"\npath = \"builtin:prosthesis\"\n\n[[mesh]]\nname = \"stem\"\npath = \"builtin:prosthesis\"\n\n[[measurement]]\nkind = \"distance\"\nnode = \"stem\"\npoints = [[0, 0, 0], [1, 0, 0]]")),
                &["render", "s.toml", "--size", "32x24", "--out", "o.png"],
                &["stem", "2 meshes or volumes"],
            ),
            None,
        ),
        with(
            case(
                "measurement-label-of-a-megabyte",
                files_and("s.toml", scene(&format!("[[measurement]]\nkind = \"distance\"\nlabel = \"{}\"\npoints = [[0, 0, 0], [1, 0, 0]]", "x".repeat(1 << 20)))),
                &["render", "s.toml", "--size", "32x24", "--out", "o.png"],
                &["label", "1048576 characters"],
            ),
            None,
        ),
        // Batches: the index and outputs never written through links, sidecars kept apart
        // from the index, shard counts bounded, merges that cost in the files present.
        with(
            case("batch-index-is-a-link", files_and("m.toml", manifest("")), &["batch", "m.toml", "--out", "out"], &["index.json", "symbolic link"]),
            Some(|d| {
                std::fs::create_dir_all(d.join("out")).unwrap();
                std::os::unix::fs::symlink("../keep.txt", d.join("out/index.json")).unwrap();
            }),
        ),
        with(
            case("batch-output-folder-is-a-link", files_and("m.toml", manifest("out = \"sub/{job}.png\"")), &["batch", "m.toml", "--out", "out"], &["sub", "symbolic link"]),
            Some(|d| {
                std::fs::create_dir_all(d.join("out")).unwrap();
                std::fs::create_dir_all(d.join("elsewhere")).unwrap();
                std::os::unix::fs::symlink("../elsewhere", d.join("out/sub")).unwrap();
            }),
        ),
        with(
            case("batch-output-is-the-manifest", files_and("m.json", manifest("depth = \"m.png\"")), &["batch", "m.json", "--out", "."], &["m.json", "input", "nothing was rendered"]),
            None,
        ),
        with(
            case("batch-output-is-a-volume", files_and("m.toml", manifest("out = \"ct.png\"")), &["batch", "m.toml", "--out", "."], &["input"]).setup_link_volume(),
            None,
        ),
        // A data file a header names is known once its job loads: the job fails before it
        // draws, and the data file is as it was.
        Case {
            after: Some(|d| match std::fs::read(d.join("out/a.png")) {
                Ok(b) if b == (0..64u8).map(|v| v * 4).collect::<Vec<u8>>() => Ok(()),
                _ => Err("out/a.png, the header's data file, was changed".into()),
            }),
            ..case(
                "batch-output-is-a-header-data-file",
                {
                    let mut f = files_and("m.toml", b"[[job]]\nname = \"a\"\nvolume = \"d.nhdr\"\nviews = [\"anterior\"]\nsizes = [[32, 24]]\nout = \"a.png\"\n".to_vec());
                    f.push(("d.nhdr", b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nencoding: raw\ndata file: out/a.png\n".to_vec()));
                    f.push(("out/a.png", (0..64u8).map(|v| v * 4).collect()));
                    f
                },
                &["batch", "m.toml", "--out", "out"],
                &["a.png", "input"],
            )
        },
        with(
            case("batch-depth-sidecar-is-the-index", files_and("m.toml", manifest("depth = \"index.png\"")), &["batch", "m.toml", "--check"], &["depth", "index"]),
            None,
        ),
        with(
            case("batch-shard-count-huge", files_and("m.toml", manifest("")), &["batch", "m.toml", "--shard", "1/18446744073709551615"], &["--shard", "at most"]),
            None,
        ),
        with(
            case("merge-of-a-huge-shard-count", files_and("out/index-1-of-4000000.json", b"{}".to_vec()), &["batch", "--merge", "out"], &["missing", "more"]),
            None,
        ),
        with(
            case("merge-of-a-shard-beyond-the-limit", files_and("out/index-1-of-18446744073709551615.json", b"{}".to_vec()), &["batch", "--merge", "out"], &["index-1-of-18446744073709551615.json", "at most"]),
            None,
        ),
    ]
}

/// Small adjustments to a case, chained where it is built.
trait CaseExt {
    /// `ct.png` is made a link to the volume before the run.
    fn setup_link_volume(self) -> Self;
}

impl CaseExt for Case {
    fn setup_link_volume(self) -> Self {
        Case {
            setup: Some(|d| std::os::unix::fs::symlink("ct.nrrd", d.join("ct.png")).unwrap()),
            ..self
        }
    }
}
