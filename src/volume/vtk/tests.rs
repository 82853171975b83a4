use super::*;
use crate::volume::loader::tests::scratch;
use std::io::Write;

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn legacy(fields: &str, data: &[u8]) -> Vec<u8> {
    let mut bytes =
        format!("# vtk DataFile Version 3.0\ntitle\nBINARY\nDATASET STRUCTURED_POINTS\n{fields}")
            .into_bytes();
    bytes.extend(data);
    bytes
}

#[test]
fn legacy_binary_is_big_endian() {
    let dir = scratch("vtk-legacy");
    let fields = "DIMENSIONS 2 1 2\nSPACING 0.5 1 2\nORIGIN 1 2 3\nPOINT_DATA 4\nSCALARS s short 1\nLOOKUP_TABLE default\n";
    let data: Vec<u8> = [-1000i16, 0, 1, 3000]
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    let loaded = load_vtk_legacy(&write(&dir, "v.vtk", &legacy(fields, &data))).unwrap();
    assert_eq!(loaded.volume.values, [-1000.0, 0.0, 1.0, 3000.0]);
    assert_eq!(
        (loaded.volume.spacing, loaded.volume.origin),
        ([0.5, 1.0, 2.0], [1.0, 2.0, 3.0])
    );
    assert_eq!(loaded.scalar_type, Some(ScalarType::I16));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn legacy_problems_are_typed_errors() {
    let dir = scratch("vtk-legacy-bad");
    let ok = "DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s unsigned_char\nLOOKUP_TABLE default\n";
    let cases = [
        ("short.vtk", legacy(ok, &[0; 7]), "needs"),
        (
            "count.vtk",
            legacy(
                "DIMENSIONS 2 2 2\nPOINT_DATA 9\nSCALARS s unsigned_char\nLOOKUP_TABLE default\n",
                &[0; 9],
            ),
            "POINT_DATA 9",
        ),
        (
            "type.vtk",
            legacy(
                "DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s quaternion\nLOOKUP_TABLE default\n",
                &[0; 8],
            ),
            "unknown scalar type",
        ),
        (
            "long.vtk",
            legacy(
                "DIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s long\nLOOKUP_TABLE default\n",
                &[0; 64],
            ),
            "long",
        ),
        (
            "vec.vtk",
            legacy(
                "DIMENSIONS 2 2 2\nPOINT_DATA 8\nVECTORS v float\n",
                &[0; 96],
            ),
            "VECTORS",
        ),
        (
            "dims.vtk",
            legacy("DIMENSIONS 2 -2 2\n", &[]),
            "DIMENSIONS needs 3 counts",
        ),
        (
            "huge.vtk",
            legacy(
                "DIMENSIONS 100000 100000 100000\nPOINT_DATA 1\nSCALARS s float\nLOOKUP_TABLE default\n",
                &[0; 8],
            ),
            "declared grid size",
        ),
        (
            "end.vtk",
            legacy("DIMENSIONS 2 2 2\n", &[]),
            "ends before LOOKUP_TABLE",
        ),
        (
            "ascii.vtk",
            b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nPOINT_DATA 8\nSCALARS s short\nLOOKUP_TABLE default\n1 2 x 4 5 6 7 8\n".to_vec(),
            "\"x\" after 2 of the 8 declared values is not a number",
        ),
        (
            "grid.vtk",
            b"# vtk DataFile Version 3.0\nt\nBINARY\nDATASET POLYDATA\n".to_vec(),
            "POLYDATA",
        ),
    ];
    for (name, bytes, expected) in cases {
        let err = load_vtk_legacy(&write(&dir, name, &bytes))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(expected) && err.contains(name),
            "{name}: {err}"
        );
    }
    std::fs::remove_dir_all(dir).ok();
}

/// A `.vti` document around one point-data array and optional appended data.
fn vti(file_attrs: &str, array: &str, appended: &[u8]) -> Vec<u8> {
    let mut bytes = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" {file_attrs}>\n\
         <ImageData WholeExtent=\"1 2 0 0 0 1\" Origin=\"10 0 0\" Spacing=\"2 1 3\" Direction=\"0 -1 0 1 0 0 0 0 1\">\n\
         <Piece Extent=\"1 2 0 0 0 1\"><PointData Scalars=\"s\">\n\
         <DataArray type=\"Float32\" Name=\"other\" format=\"binary\">AAAA</DataArray>\n\
         {array}\n</PointData></Piece></ImageData>\n"
    )
    .into_bytes();
    if !appended.is_empty() {
        bytes.extend(b"<AppendedData encoding=\"raw\">_");
        bytes.extend(appended);
        bytes.extend(b"</AppendedData>");
    }
    bytes.extend(b"</VTKFile>\n");
    bytes
}

const VALUES: [u16; 4] = [1, 2, 300, 40000];

fn le16(values: &[u16]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}

/// VTK's compressed layout: a header of `word`-byte counts, then the zlib blocks.
fn compressed(word: usize, block: usize, data: &[u8]) -> (Vec<u8>, Vec<u8>) {
    let blocks: Vec<Vec<u8>> = data.chunks(block).map(zlib).collect();
    let last = data.len() % block;
    let mut header = vec![blocks.len() as u64, block as u64, last as u64];
    header.extend(blocks.iter().map(|b| b.len() as u64));
    let header: Vec<u8> = header
        .iter()
        .flat_map(|w| w.to_le_bytes()[..word].to_vec())
        .collect();
    (header, blocks.concat())
}

#[test]
fn vti_inline_appended_and_compressed_arrays() {
    let dir = scratch("vti");
    let data = le16(&VALUES);
    let array = |attrs: &str, text: &str| {
        format!("<DataArray type=\"UInt16\" Name=\"s\" {attrs}>{text}</DataArray>")
    };
    let mut plain = 8u32.to_le_bytes().to_vec();
    plain.extend(&data);
    let inline = vti("", &array("format=\"binary\"", &BASE64.encode(&plain)), &[]);
    let expected = load_vti(&write(&dir, "inline.vti", &inline)).unwrap();
    assert_eq!(expected.volume.values, VALUES.map(f32::from));
    assert_eq!(expected.volume.dims, [2, 1, 2]);
    // Direction rows (0 -1 0), (1 0 0): the x axis runs along +y, the y axis along -x; the
    // extent starts at x index 1, one 2-unit step along +y from the origin.
    assert_eq!(
        expected.volume.direction,
        DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z)
    );
    assert_eq!(
        (expected.volume.spacing, expected.volume.origin),
        ([2.0, 1.0, 3.0], [10.0, 2.0, 0.0])
    );
    let appended = vti(
        "",
        &array("format=\"appended\" offset=\"3\"", ""),
        &[[9u8; 3].as_slice(), &plain].concat(),
    );
    assert_eq!(
        load_vti(&write(&dir, "appended.vti", &appended)).unwrap(),
        expected
    );
    let zlib_attrs = "compressor=\"vtkZLibDataCompressor\" header_type=\"UInt64\"";
    let (header, blocks) = compressed(8, 4, &data);
    let text = format!("{}{}", BASE64.encode(&header), BASE64.encode(&blocks));
    let inline_z = vti(zlib_attrs, &array("format=\"binary\"", &text), &[]);
    assert_eq!(
        load_vti(&write(&dir, "inline_z.vti", &inline_z)).unwrap(),
        expected
    );
    let (header, blocks) = compressed(4, 6, &data);
    let raw_z = vti(
        "compressor=\"vtkZLibDataCompressor\"",
        &array("format=\"appended\" offset=\"0\"", ""),
        &[header, blocks].concat(),
    );
    assert_eq!(
        load_vti(&write(&dir, "raw_z.vti", &raw_z)).unwrap(),
        expected
    );
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn vti_problems_are_typed_errors() {
    let dir = scratch("vti-bad");
    let data = le16(&VALUES);
    let array = |attrs: &str| {
        format!("<DataArray type=\"UInt16\" Name=\"s\" format=\"appended\" offset=\"0\" {attrs}/>")
    };
    let z = "compressor=\"vtkZLibDataCompressor\"";
    let (header, mut blocks) = compressed(4, 8, &data);
    let mut past = header.clone();
    let longer = zlib(&[data.as_slice(), &[0]].concat());
    past[12..16].copy_from_slice(&(longer.len() as u32).to_le_bytes());
    // Inline data end at </DataArray>; raw appended data would run on to the file's end.
    let truncated = [8u32.to_le_bytes().as_slice(), &data[..5]].concat();
    let inline_short = format!(
        "<DataArray type=\"UInt16\" Name=\"s\" format=\"binary\">{}</DataArray>",
        BASE64.encode(truncated)
    );
    let mut huge = header.clone();
    huge[12..16].copy_from_slice(&10_000u32.to_le_bytes());
    let mut sized = 7u32.to_le_bytes().to_vec();
    sized.extend(&data);
    let cases = [
        (
            "past.vti",
            vti(z, &array(""), &[past, longer].concat()),
            "inflate past",
        ),
        (
            "blocks.vti",
            vti(z, &array(""), &[huge, blocks.clone()].concat()),
            "block 0 runs past",
        ),
        ("stated.vti", vti("", &array(""), &sized), "holds 7 bytes"),
        ("short.vti", vti("", &inline_short, &[]), "needs 8 bytes"),
        (
            "order.vti",
            vti("byte_order=\"Middle\"", &array(""), &data),
            "byte_order",
        ),
        (
            "lzma.vti",
            vti("compressor=\"vtkLZMADataCompressor\"", &array(""), &data),
            "vtkLZMADataCompressor",
        ),
        (
            "type.vti",
            vti("", &array("").replace("UInt16", "Bits"), &data),
            "unknown DataArray type",
        ),
        (
            "comp.vti",
            vti("", &array("NumberOfComponents=\"3\""), &data),
            "multi-component",
        ),
        (
            "ascii.vti",
            vti(
                "",
                "<DataArray type=\"UInt16\" Name=\"s\" format=\"ascii\">1 2 x</DataArray>",
                &[],
            ),
            "\"x\" in the text data is not a number",
        ),
        (
            "poly.vti",
            b"<VTKFile type=\"PolyData\"></VTKFile>".to_vec(),
            "PolyData",
        ),
        (
            "offset.vti",
            vti(
                "",
                &array("").replace("offset=\"0\"", "offset=\"99\""),
                &data,
            ),
            "offset",
        ),
    ];
    for (name, bytes, expected) in cases {
        let err = load_vti(&write(&dir, name, &bytes))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(expected) && err.contains(name),
            "{name}: {err}"
        );
    }
    let end = blocks.len() - 1;
    blocks[end] ^= 0xff;
    let corrupt = vti(z, &array(""), &[header, blocks].concat());
    let err = load_vti(&write(&dir, "corrupt.vti", &corrupt)).unwrap_err();
    assert!(
        matches!(
            err,
            VolumeError::Decompress { .. } | VolumeError::InflatesShort { .. }
        ),
        "{err}"
    );
    std::fs::remove_dir_all(dir).ok();
}
