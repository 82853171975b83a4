//! VTK image volumes: legacy `STRUCTURED_POINTS` files and XML `ImageData` (`.vti`) files.
//!
//! **Legacy** (`# vtk DataFile Version x.y`): `BINARY` data (big-endian, as the VTK file-format
//! specification fixes it) or `ASCII` (numbers separated by white space), `DATASET
//! STRUCTURED_POINTS` with `DIMENSIONS`, `SPACING` (or the old `ASPECT_RATIO`; a negative
//! step runs its axis the other way, as VTK keeps it and SimpleITK flips it: each voxel lands
//! at `ORIGIN + SPACING x index` either way) and `ORIGIN`, then `POINT_DATA n` and
//! one-component `SCALARS` of an 8- to 32-bit integer type, `float` or `double`, followed by a
//! `LOOKUP_TABLE` line and the values. The file's length is checked against the declared size
//! before allocating.
//!
//! **XML** (`<VTKFile type="ImageData">`): one `Piece` covering the `WholeExtent`; the point-data
//! array named by `PointData Scalars` (else the first), one component; `format="ascii"`,
//! `format="binary"` (inline base64) or `format="appended"` (`AppendedData` base64 or raw); no
//! compression, `vtkZLibDataCompressor` or `vtkLZ4DataCompressor`, with `header_type` `UInt32`
//! or `UInt64`; `byte_order` little or big;
//! `Origin`, `Spacing` and `Direction` (row-major, columns the axes). A `WholeExtent` that does
//! not start at 0 moves the origin to the first voxel. The whole file is read into memory
//! (never more than its length); compressed blocks inflate to exactly their declared sizes.
//!
//! Not read (a typed [`VolumeError::Unsupported`]): other dataset types,
//! cell data, vectors and multi-component arrays, 64-bit integers, LZMA compression, and
//! multi-piece files.
//!
//! VTK has no anatomical frame: coordinates are taken as they are in the project's RAS world,
//! unless the caller says they are LPS ([`super::loader::LoadOptions::coordinate_frame`]), as
//! in files ITK-based tools write.

use std::path::Path;

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use flate2::read::ZlibDecoder;
use glam::{DMat3, DVec3};

use super::loader::{
    HeaderLines, LoadedVolume, Placement, VolumeFormat, expect_end, header_error, inflate_values,
    io_error, text_values, unsupported,
};
use super::loader::{checked_voxels, decode};
use super::{
    ByteOrder, CpuVolume, RawSpec, ScalarFormat, ScalarType, VolumeError, Voxels, load_raw,
};

/// Loads a legacy VTK `STRUCTURED_POINTS` file with binary scalars.
pub fn load_vtk_legacy(path: &Path) -> Result<LoadedVolume, VolumeError> {
    let header = LegacyHeader::read(path)?;
    // A negative SPACING steps the other way along its axis: VTK keeps it so and SimpleITK
    // flips the axis, which put every voxel at the same point (origin + spacing x index).
    let [sx, sy, sz] = header.spacing;
    let columns = [DVec3::X * sx, DVec3::Y * sy, DVec3::Z * sz];
    let placement = Placement::from_columns(path, columns, DVec3::from(header.origin))?;
    let volume = if header.ascii {
        legacy_ascii_values(path, &header)?
    } else {
        let spec = RawSpec {
            header_bytes: header.data_offset,
            ..RawSpec::new(header.dims, header.scalar, ByteOrder::Big)
        };
        load_raw(path, &spec)?
    };
    Ok(LoadedVolume {
        volume: placement.apply(volume),
        format: VolumeFormat::VtkLegacy,
        scalar_type: Some(header.scalar),
        patient_frame: false,
    })
}

/// The values of an `ASCII` legacy file: white-space-separated numbers after the header,
/// exactly as many as the grid has voxels; a keyword after them (VTK writes `METADATA` blocks
/// and further arrays there) ends them.
fn legacy_ascii_values(path: &Path, header: &LegacyHeader) -> Result<CpuVolume, VolumeError> {
    use std::io::{Read, Seek, SeekFrom};
    // Text values are held as f32.
    let count = usize::try_from(grid_count(path, header.dims, ScalarType::F32)?)
        .map_err(|_| header_error(path, "declared size overflows"))?;
    let mut file = crate::input::open_regular(path).map_err(io_error(path))?;
    let len = file.metadata().map_err(io_error(path))?.len();
    // Each value takes at least two characters (a digit and a separator): a file too short
    // for the grid is refused before any value memory is taken.
    let available = len.saturating_sub(header.data_offset);
    if available.saturating_add(1) / 2 < count as u64 {
        let message = format!(
            "the ASCII data take {available} bytes, too few for the {count} values declared"
        );
        return Err(header_error(path, message));
    }
    file.seek(SeekFrom::Start(header.data_offset))
        .map_err(io_error(path))?;
    let mut text = String::new();
    file.take(available)
        .read_to_string(&mut text)
        .map_err(|e| header_error(path, format!("the ASCII data are not text: {e}")))?;
    let mut words = text.split_whitespace();
    let mut values = Vec::with_capacity(count);
    for word in words.by_ref().take(count) {
        let value: f64 = word.parse().map_err(|_| {
            header_error(
                path,
                format!(
                    "{word:?} after {} of the {count} declared values is not a number",
                    values.len()
                ),
            )
        })?;
        values.push(value as f32);
    }
    if values.len() < count {
        let message = format!(
            "the ASCII data hold {} values where {count} are declared",
            values.len()
        );
        return Err(header_error(path, message));
    }
    if words.next().is_some_and(|w| w.parse::<f64>().is_ok()) {
        let message = format!("the ASCII data hold more than the {count} values declared");
        return Err(header_error(path, message));
    }
    Ok(CpuVolume {
        dims: header.dims,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: values.into(),
    })
}

/// What a legacy header says.
struct LegacyHeader {
    /// `ASCII` data (else `BINARY`).
    ascii: bool,
    dims: [u32; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    scalar: ScalarType,
    data_offset: u64,
}

impl LegacyHeader {
    fn read(path: &Path) -> Result<Self, VolumeError> {
        let mut lines = HeaderLines::open(path)?;
        let first = lines.next_line()?.unwrap_or_default();
        if !first.starts_with("# vtk DataFile") {
            return Err(header_error(path, "no `# vtk DataFile` first line"));
        }
        // The title line is free text, even empty; blank lines elsewhere are skipped.
        let _title = lines.next_line()?;
        let mut partial = PartialLegacy::default();
        while let Some(line) = lines.next_line()? {
            let words: Vec<&str> = line.split_whitespace().collect();
            if partial.take(path, lines.number(), &words)? {
                return partial.finish(path, lines.offset());
            }
        }
        Err(header_error(path, "ends before LOOKUP_TABLE and the data"))
    }
}

/// The legacy header's keywords seen so far.
#[derive(Default)]
struct PartialLegacy {
    binary: bool,
    ascii: bool,
    dataset: bool,
    dims: Option<[u32; 3]>,
    spacing: Option<[f64; 3]>,
    origin: Option<[f64; 3]>,
    points: Option<u64>,
    scalar: Option<ScalarType>,
}

impl PartialLegacy {
    /// Takes one header line; `true` once the `LOOKUP_TABLE` line before the data is read.
    fn take(&mut self, path: &Path, line: usize, words: &[&str]) -> Result<bool, VolumeError> {
        let at = |message: String| header_error(path, format!("line {line}: {message}"));
        let Some(keyword) = words.first().map(|w| w.to_ascii_uppercase()) else {
            return Ok(false);
        };
        let rest = &words[1..];
        let three = || numbers(rest).ok_or_else(|| at(format!("{keyword} needs 3 numbers")));
        match (keyword.as_str(), rest) {
            ("BINARY", []) => self.binary = true,
            ("ASCII", []) => self.ascii = true,
            ("DATASET", [kind]) if kind.eq_ignore_ascii_case("STRUCTURED_POINTS") => {
                self.dataset = true;
            }
            ("DIMENSIONS", _) => {
                let dims = numbers(rest).ok_or_else(|| at("DIMENSIONS needs 3 counts".into()))?;
                self.dims = Some(dims);
            }
            ("SPACING" | "ASPECT_RATIO", _) => self.spacing = Some(three()?),
            ("ORIGIN", _) => self.origin = Some(three()?),
            ("POINT_DATA", [n]) => {
                let n = n
                    .parse()
                    .map_err(|_| at(format!("POINT_DATA {n:?} is not a count")))?;
                self.points = Some(n);
            }
            ("SCALARS", [_name, kind, components @ ..]) => {
                if components.first().is_some_and(|c| *c != "1") {
                    return Err(unsupported(path, "multi-component SCALARS"));
                }
                self.scalar = Some(match legacy_type(kind) {
                    Some(Some(scalar)) => scalar,
                    Some(None) => return Err(unsupported(path, format!("scalar type {kind}"))),
                    None => return Err(at(format!("unknown scalar type {kind:?}"))),
                });
            }
            ("LOOKUP_TABLE", _) if self.scalar.is_some() => return Ok(true),
            // Other datasets, cell data, fields, vectors, or keywords out of order.
            _ => {
                return Err(unsupported(
                    path,
                    format!("line {line}: {}", words.join(" ")),
                ));
            }
        }
        Ok(false)
    }

    fn finish(self, path: &Path, data_offset: u64) -> Result<LegacyHeader, VolumeError> {
        let missing = |what: &str| header_error(path, format!("no {what} before the data"));
        if self.binary == self.ascii {
            return Err(missing("BINARY or ASCII (one of them)"));
        }
        if !self.dataset {
            return Err(missing("DATASET STRUCTURED_POINTS"));
        }
        let dims = self.dims.ok_or_else(|| missing("DIMENSIONS"))?;
        let scalar = self.scalar.ok_or_else(|| missing("SCALARS"))?;
        let held = if self.ascii { ScalarType::F32 } else { scalar };
        let count = grid_count(path, dims, held)?;
        let points = self.points.ok_or_else(|| missing("POINT_DATA"))?;
        if points != count {
            let message = format!("POINT_DATA {points} but DIMENSIONS {dims:?} make {count}");
            return Err(header_error(path, message));
        }
        Ok(LegacyHeader {
            ascii: self.ascii,
            dims,
            spacing: self.spacing.unwrap_or([1.0; 3]),
            origin: self.origin.unwrap_or([0.0; 3]),
            scalar,
            data_offset,
        })
    }
}

/// Exactly three parsed words.
fn numbers<T: std::str::FromStr>(words: &[&str]) -> Option<[T; 3]> {
    let parsed: Option<Vec<T>> = words.iter().map(|w| w.parse().ok()).collect();
    parsed?.try_into().ok()
}

fn grid_count(path: &Path, dims: [u32; 3], scalar: ScalarType) -> Result<u64, VolumeError> {
    checked_voxels(path, dims, scalar)
}

/// A legacy scalar type name: `Some(None)` for a known type that is not read, `None` for an
/// unknown name.
fn legacy_type(name: &str) -> Option<Option<ScalarType>> {
    Some(Some(match name.to_ascii_lowercase().as_str() {
        "unsigned_char" => ScalarType::U8,
        "char" | "signed_char" => ScalarType::I8,
        "unsigned_short" => ScalarType::U16,
        "short" => ScalarType::I16,
        "unsigned_int" => ScalarType::U32,
        "int" => ScalarType::I32,
        "float" => ScalarType::F32,
        "double" => ScalarType::F64,
        // `long` is 4 or 8 bytes depending on the writer's platform.
        "bit" | "unsigned_long" | "long" | "vtktypeint64" | "vtktypeuint64" => return Some(None),
        _ => return None,
    }))
}

/// Loads a VTK XML `ImageData` (`.vti`) file.
pub fn load_vti(path: &Path) -> Result<LoadedVolume, VolumeError> {
    let bytes = crate::input::read_regular(path, u64::MAX).map_err(io_error(path))?;
    let xml = Xml::split(path, &bytes)?;
    let encoding = Encoding::from_file_tag(path, &xml.tag("VTKFile")?)?;
    let grid = Grid::read(path, &xml)?;
    let array = xml.scalars_array()?;
    let format = array_format(path, &array, encoding.order)?;
    let blob = xml.array_data(&array)?;
    // Text values are held as f32.
    let held = match blob {
        Blob::Ascii(_) => ScalarType::F32,
        _ => format.scalar,
    };
    let count = grid_count(path, grid.dims, held)?;
    let values = encoding.values(path, blob, format, count)?;
    let volume = CpuVolume {
        dims: grid.dims,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values,
    };
    Ok(LoadedVolume {
        volume: grid.placement.apply(volume),
        format: VolumeFormat::VtkXml,
        scalar_type: Some(format.scalar),
        patient_frame: false,
    })
}

/// One XML start tag and its attributes.
struct Tag<'a> {
    attrs: Vec<(&'a str, &'a str)>,
    /// Byte offset just past the tag's `>`.
    end: usize,
}

impl<'a> Tag<'a> {
    fn attr(&self, name: &str) -> Option<&'a str> {
        self.attrs.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
    }
}

/// The XML text of a `.vti` file, and its appended data if any.
struct Xml<'a> {
    path: &'a Path,
    text: &'a str,
    /// The bytes after the `_` that starts the appended data, with their encoding.
    appended: Option<(&'a [u8], &'a str)>,
}

impl<'a> Xml<'a> {
    /// Separates the XML text from appended data, which may be raw binary.
    fn split(path: &'a Path, bytes: &'a [u8]) -> Result<Self, VolumeError> {
        let marker = b"<AppendedData";
        let start = bytes.windows(marker.len()).position(|w| w == marker);
        let (head, appended) = match start {
            None => (bytes, None),
            Some(at) => {
                let underscore = bytes[at..].iter().position(|&b| b == b'_');
                let u = at
                    + underscore
                        .ok_or_else(|| header_error(path, "AppendedData without its `_`"))?;
                // The data run to the closing tag (the last one: raw data may hold its bytes).
                let close = b"</AppendedData>";
                let end = bytes
                    .windows(close.len())
                    .rposition(|w| w == close)
                    .filter(|&e| e > u)
                    .unwrap_or(bytes.len());
                (&bytes[..u], Some(&bytes[u + 1..end]))
            }
        };
        let text = std::str::from_utf8(head)
            .map_err(|_| header_error(path, "the XML is not UTF-8 text"))?;
        let mut xml = Self {
            path,
            text,
            appended: None,
        };
        if let Some(data) = appended {
            let encoding = xml
                .tag("AppendedData")?
                .attr("encoding")
                .unwrap_or("base64");
            xml.appended = Some((data, encoding));
        }
        Ok(xml)
    }

    /// The first start tag named `name` at or after byte `from`.
    fn find(&self, name: &str, from: usize) -> Result<Option<Tag<'a>>, VolumeError> {
        let mut search = from;
        while let Some(found) = self.text.get(search..).and_then(|t| t.find('<')) {
            let at = search + found + 1;
            let after = self.text[at..]
                .strip_prefix(name)
                .and_then(|r| r.chars().next());
            if after.is_some_and(|c| c.is_whitespace() || c == '>' || c == '/') {
                let tag = parse_tag(self.text, at + name.len());
                return tag
                    .map(Some)
                    .ok_or_else(|| header_error(self.path, format!("malformed <{name}> tag")));
            }
            search = at;
        }
        Ok(None)
    }

    fn tag(&self, name: &str) -> Result<Tag<'a>, VolumeError> {
        self.find(name, 0)?
            .ok_or_else(|| header_error(self.path, format!("no <{name}> element")))
    }

    /// The `DataArray` of the point data that `Scalars` names, else the first one.
    fn scalars_array(&self) -> Result<Tag<'a>, VolumeError> {
        let Some(point_data) = self.find("PointData", 0)? else {
            return Err(unsupported(
                self.path,
                "no PointData (cell data are not read)",
            ));
        };
        let close = self.text[point_data.end..]
            .find("</PointData>")
            .map_or(self.text.len(), |c| point_data.end + c);
        let wanted = point_data.attr("Scalars");
        let mut first = None;
        let mut from = point_data.end;
        while let Some(array) = self.find("DataArray", from)?.filter(|a| a.end <= close) {
            from = array.end;
            if wanted.is_none() || array.attr("Name") == wanted {
                return Ok(array);
            }
            first.get_or_insert(array);
        }
        first.ok_or_else(|| header_error(self.path, "PointData holds no DataArray"))
    }

    /// The encoded bytes of an array's data: inline base64, or appended from its offset.
    fn array_data(&self, array: &Tag<'a>) -> Result<Blob<'a>, VolumeError> {
        match array.attr("format") {
            Some("binary") => {
                let end = self.text[array.end..].find("</DataArray>");
                let end = end.ok_or_else(|| header_error(self.path, "DataArray not closed"))?;
                Ok(Blob::Base64(
                    &self.text.as_bytes()[array.end..array.end + end],
                ))
            }
            Some("ascii") => {
                let end = self.text[array.end..].find("</DataArray>");
                let end = end.ok_or_else(|| header_error(self.path, "DataArray not closed"))?;
                Ok(Blob::Ascii(&self.text[array.end..array.end + end]))
            }
            Some("appended") => self.appended_data(array),
            other => {
                let feature = format!(
                    "DataArray format {}; only ascii, binary and appended are read",
                    other.unwrap_or("(none)")
                );
                Err(unsupported(self.path, feature))
            }
        }
    }

    fn appended_data(&self, array: &Tag<'a>) -> Result<Blob<'a>, VolumeError> {
        let error = |message: &str| header_error(self.path, message);
        let (data, encoding) = self
            .appended
            .ok_or_else(|| error("appended array but no AppendedData"))?;
        let offset: usize = array
            .attr("offset")
            .and_then(|o| o.trim().parse().ok())
            .ok_or_else(|| error("appended DataArray without a valid offset"))?;
        let data = data
            .get(offset..)
            .ok_or_else(|| error("DataArray offset past the appended data"))?;
        match encoding {
            "base64" => Ok(Blob::Base64(data)),
            "raw" => Ok(Blob::Raw(data)),
            other => Err(unsupported(
                self.path,
                format!("AppendedData encoding {other}"),
            )),
        }
    }
}

/// The attributes of the tag whose name ends at `at`, up to its `>`; `None` if malformed.
fn parse_tag(text: &str, mut at: usize) -> Option<Tag<'_>> {
    let mut attrs = Vec::new();
    loop {
        let rest = text.get(at..)?.trim_start();
        if let Some(after) = rest.strip_prefix("/>").or_else(|| rest.strip_prefix('>')) {
            return Some(Tag {
                attrs,
                end: text.len() - after.len(),
            });
        }
        let (name, value) = rest.split_once('=')?;
        let value = value.trim_start();
        let quote = value.chars().next().filter(|q| *q == '"' || *q == '\'')?;
        let close = value[1..].find(quote)?;
        attrs.push((name.trim(), &value[1..1 + close]));
        // Past the closing quote.
        at = text.len() - value.len() + close + 2;
    }
}

/// An array's bytes, still base64-encoded or raw.
#[derive(Clone, Copy)]
enum Blob<'a> {
    Base64(&'a [u8]),
    Raw(&'a [u8]),
    /// `format="ascii"`: numbers as text.
    Ascii(&'a str),
}

/// The value type of a `DataArray`, which must have one component.
fn array_format(
    path: &Path,
    array: &Tag<'_>,
    order: ByteOrder,
) -> Result<ScalarFormat, VolumeError> {
    if array
        .attr("NumberOfComponents")
        .is_some_and(|n| n.trim() != "1")
    {
        return Err(unsupported(path, "multi-component point data"));
    }
    let name = array.attr("type").unwrap_or("");
    let scalar = match name {
        "Int8" => ScalarType::I8,
        "UInt8" => ScalarType::U8,
        "Int16" => ScalarType::I16,
        "UInt16" => ScalarType::U16,
        "Int32" => ScalarType::I32,
        "UInt32" => ScalarType::U32,
        "Float32" => ScalarType::F32,
        "Float64" => ScalarType::F64,
        "Int64" | "UInt64" => return Err(unsupported(path, format!("DataArray type {name}"))),
        _ => {
            return Err(header_error(
                path,
                format!("unknown DataArray type {name:?}"),
            ));
        }
    };
    Ok(ScalarFormat { scalar, order })
}

/// The size and placement of the image.
struct Grid {
    dims: [u32; 3],
    placement: Placement,
}

impl Grid {
    fn read(path: &Path, xml: &Xml<'_>) -> Result<Self, VolumeError> {
        let image = xml.tag("ImageData")?;
        let extent = image
            .attr("WholeExtent")
            .ok_or_else(|| header_error(path, "ImageData without WholeExtent"))?;
        let piece = xml.tag("Piece")?;
        let same = |e: &str| e.split_whitespace().eq(extent.split_whitespace());
        if xml.text.matches("<Piece").count() != 1 || !piece.attr("Extent").is_some_and(same) {
            return Err(unsupported(
                path,
                "pieces other than one covering the WholeExtent",
            ));
        }
        let (dims, start) = extent_dims(path, extent)?;
        let origin: [f64; 3] = attr_numbers(path, &image, "Origin", [0.0; 3])?;
        let spacing: [f64; 3] = attr_numbers(path, &image, "Spacing", [1.0; 3])?;
        let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let rows: [f64; 9] = attr_numbers(path, &image, "Direction", identity)?;
        // Direction is written row by row; its columns are the grid axes.
        let direction = DMat3::from_cols_array(&rows).transpose();
        let steps = DMat3::from_cols(
            direction.x_axis * spacing[0],
            direction.y_axis * spacing[1],
            direction.z_axis * spacing[2],
        );
        // Voxel (0, 0, 0) of the loaded grid is the extent's first index.
        let first = DVec3::from(origin) + steps * start;
        let placement =
            Placement::from_columns(path, [steps.x_axis, steps.y_axis, steps.z_axis], first)?;
        Ok(Self { dims, placement })
    }
}

/// The grid size of an extent `x0 x1 y0 y1 z0 z1`, and its first index.
fn extent_dims(path: &Path, extent: &str) -> Result<([u32; 3], DVec3), VolumeError> {
    let bad = || {
        header_error(
            path,
            format!("WholeExtent {extent:?} is not 6 bounds of a non-empty grid"),
        )
    };
    let parsed: Option<Vec<i64>> = extent.split_whitespace().map(|w| w.parse().ok()).collect();
    let e: [i64; 6] = parsed.and_then(|p| p.try_into().ok()).ok_or_else(bad)?;
    let mut dims = [0u32; 3];
    for (axis, d) in dims.iter_mut().enumerate() {
        let n = e[2 * axis + 1]
            .checked_sub(e[2 * axis])
            .and_then(|n| n.checked_add(1));
        *d = n
            .and_then(|n| u32::try_from(n).ok())
            .filter(|&n| n > 0)
            .ok_or_else(bad)?;
    }
    Ok((dims, DVec3::new(e[0] as f64, e[2] as f64, e[4] as f64)))
}

/// `N` numbers from an attribute, or `default` when it is absent.
fn attr_numbers<const N: usize>(
    path: &Path,
    tag: &Tag<'_>,
    name: &str,
    default: [f64; N],
) -> Result<[f64; N], VolumeError> {
    let Some(value) = tag.attr(name) else {
        return Ok(default);
    };
    let parsed: Option<Vec<f64>> = value.split_whitespace().map(|w| w.parse().ok()).collect();
    parsed
        .and_then(|p| p.try_into().ok())
        .ok_or_else(|| header_error(path, format!("{name} {value:?} is not {N} numbers")))
}

/// How the file encodes binary data: byte order, header word size and compression.
struct Encoding {
    order: ByteOrder,
    /// Bytes per header word (4 for `UInt32`, 8 for `UInt64`).
    word: usize,
    compressor: Option<Compressor>,
}

/// How the blocks of a compressed array are compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Compressor {
    /// `vtkZLibDataCompressor`.
    Zlib,
    /// `vtkLZ4DataCompressor`: LZ4 block format, each block's size known from the header.
    Lz4,
}

impl Encoding {
    /// Reads the `VTKFile` element, which must describe `ImageData`.
    fn from_file_tag(path: &Path, file: &Tag<'_>) -> Result<Self, VolumeError> {
        let kind = file.attr("type").unwrap_or("");
        if kind != "ImageData" {
            return Err(unsupported(
                path,
                format!("VTKFile type {kind:?}; only ImageData is read"),
            ));
        }
        let order = match file.attr("byte_order") {
            Some("LittleEndian") | None => ByteOrder::Little,
            Some("BigEndian") => ByteOrder::Big,
            Some(other) => {
                return Err(header_error(
                    path,
                    format!("byte_order {other:?} is neither LittleEndian nor BigEndian"),
                ));
            }
        };
        let word = match file.attr("header_type") {
            Some("UInt32") | None => 4,
            Some("UInt64") => 8,
            Some(other) => {
                return Err(header_error(
                    path,
                    format!("header_type {other:?} is neither UInt32 nor UInt64"),
                ));
            }
        };
        let compressor = match file.attr("compressor") {
            None | Some("") => None,
            Some("vtkZLibDataCompressor") => Some(Compressor::Zlib),
            Some("vtkLZ4DataCompressor") => Some(Compressor::Lz4),
            Some(other) => {
                return Err(unsupported(
                    path,
                    format!(
                        "compressor {other}; vtkZLibDataCompressor and vtkLZ4DataCompressor are read"
                    ),
                ));
            }
        };
        Ok(Self {
            order,
            word,
            compressor,
        })
    }

    /// Header word `index` of `bytes`, if there.
    fn word_at(&self, bytes: &[u8], index: usize) -> Option<u64> {
        let start = index.checked_mul(self.word)?;
        let w = bytes.get(start..start.checked_add(self.word)?)?;
        let mut b = [0u8; 8];
        match self.order {
            ByteOrder::Little => {
                b[..self.word].copy_from_slice(w);
                Some(u64::from_le_bytes(b))
            }
            ByteOrder::Big => {
                b[8 - self.word..].copy_from_slice(w);
                Some(u64::from_be_bytes(b))
            }
        }
    }

    /// The array's `count` values from its encoded bytes.
    fn values(
        &self,
        path: &Path,
        blob: Blob<'_>,
        format: ScalarFormat,
        count: u64,
    ) -> Result<Voxels, VolumeError> {
        let overflow = || header_error(path, "declared size overflows");
        let bytes = count
            .checked_mul(format.scalar.size() as u64)
            .ok_or_else(overflow)?;
        let count = usize::try_from(count).map_err(|_| overflow())?;
        if let Blob::Ascii(text) = blob {
            // VTK never compresses text arrays.
            let mut out = Voxels::F32(Vec::with_capacity(count.min(1 << 24)));
            text_values(path, text, count, &mut out)?;
            return Ok(out);
        }
        if self.compressor.is_some() {
            let (header, data) = self.split_compressed(path, blob)?;
            return self.inflate_blocks(path, &header, &data, format, (count, bytes));
        }
        let data = match blob {
            // Header and values are one base64 stream; an appended array is followed by the
            // next one's, so only this one's characters are decoded.
            Blob::Base64(text) => {
                let text = without_whitespace(text);
                let want = usize::try_from(bytes)
                    .ok()
                    .and_then(|b| b.checked_add(self.word))
                    .map(encoded_len)
                    .ok_or_else(overflow)?;
                base64(path, text.get(..want).unwrap_or(&text))?
            }
            Blob::Raw(data) => data.to_vec(),
            Blob::Ascii(_) => unreachable!("text arrays are read above"),
        };
        let stated = self
            .word_at(&data, 0)
            .ok_or_else(|| header_error(path, "array data shorter than its header"))?;
        if stated != bytes {
            return Err(header_error(
                path,
                format!("array holds {stated} bytes but the extent needs {bytes}"),
            ));
        }
        let body = &data[self.word..];
        let values = body
            .get(..count * format.scalar.size())
            .ok_or(VolumeError::TooShort {
                path: path.into(),
                expected: bytes,
                actual: body.len() as u64,
            })?;
        let mut out = Voxels::new(format.scalar);
        out.reserve_capped(count, count);
        decode(values, format.scalar, format.order, &mut out);
        Ok(out)
    }

    /// The compression header and the compressed bytes behind it. In base64, VTK encodes the
    /// header on its own (with its own padding), then all blocks together.
    fn split_compressed(
        &self,
        path: &Path,
        blob: Blob<'_>,
    ) -> Result<(Vec<u8>, Vec<u8>), VolumeError> {
        let short = || header_error(path, "compressed array shorter than its header");
        match blob {
            Blob::Raw(data) => {
                let blocks = self.word_at(data, 0).ok_or_else(short)?;
                let len = header_len(self.word, blocks)
                    .filter(|&l| l <= data.len())
                    .ok_or_else(short)?;
                Ok((data[..len].to_vec(), data[len..].to_vec()))
            }
            Blob::Ascii(_) => Err(header_error(path, "a compressed array written as text")),
            Blob::Base64(text) => {
                let text = without_whitespace(text);
                // The first base64 groups covering one header word give the block count.
                let first = base64(path, text.get(..encoded_len(self.word)).ok_or_else(short)?)?;
                let blocks = self.word_at(&first, 0).ok_or_else(short)?;
                let len = header_len(self.word, blocks)
                    .map(encoded_len)
                    .filter(|&l| l <= text.len())
                    .ok_or_else(short)?;
                let header = base64(path, &text[..len])?;
                // The blocks' compressed sizes say how many characters follow: an appended
                // array is followed by the next one's.
                let mut compressed = 0usize;
                for i in 0..blocks {
                    let size = usize::try_from(i + 3)
                        .ok()
                        .and_then(|i| self.word_at(&header, i))
                        .and_then(|s| usize::try_from(s).ok())
                        .ok_or_else(short)?;
                    compressed = compressed.checked_add(size).ok_or_else(short)?;
                }
                let end = len
                    .checked_add(encoded_len(compressed))
                    .filter(|&e| e <= text.len())
                    .ok_or_else(|| header_error(path, "compressed blocks run past the data"))?;
                Ok((header, base64(path, &text[len..end])?))
            }
        }
    }

    /// Inflates each block to exactly its declared size; together they must make the array.
    fn inflate_blocks(
        &self,
        path: &Path,
        header: &[u8],
        data: &[u8],
        format: ScalarFormat,
        (count, bytes): (usize, u64),
    ) -> Result<Voxels, VolumeError> {
        let word = |i: u64| {
            let word = usize::try_from(i)
                .ok()
                .and_then(|i| self.word_at(header, i));
            word.ok_or_else(|| header_error(path, "truncated compression header"))
        };
        let (blocks, block, last) = (word(0)?, word(1)?, word(2)?);
        check_blocks(
            path,
            (blocks, block, last),
            format.scalar.size() as u64,
            bytes,
        )?;
        let mut out = Voxels::new(format.scalar);
        let mut at = 0usize;
        for i in 0..blocks {
            let end = usize::try_from(word(3 + i)?)
                .ok()
                .and_then(|s| at.checked_add(s))
                .filter(|&e| e <= data.len());
            let end =
                end.ok_or_else(|| header_error(path, format!("block {i} runs past the data")))?;
            let inflated = if i + 1 == blocks && last != 0 {
                last
            } else {
                block
            };
            let block = &data[at..end];
            if self.compressor == Some(Compressor::Lz4) {
                // LZ4 expands a byte to at most 255 (a run of matches), so a block that claims
                // more is refused before its output is allocated.
                if inflated > (block.len() as u64).saturating_mul(255).saturating_add(16) {
                    let message = format!(
                        "block {i}: {} LZ4 bytes cannot inflate to the {inflated} declared",
                        block.len()
                    );
                    return Err(header_error(path, message));
                }
                let mut bytes = vec![0u8; inflated as usize];
                match lz4_flex::block::decompress_into(block, &mut bytes) {
                    Ok(n) if n as u64 == inflated => {}
                    Ok(n) => {
                        return Err(VolumeError::InflatesShort {
                            path: path.into(),
                            expected: inflated,
                            actual: n as u64,
                        });
                    }
                    Err(e) => {
                        return Err(header_error(path, format!("block {i}: bad LZ4 data: {e}")));
                    }
                }
                decode(&bytes, format.scalar, format.order, &mut out);
            } else {
                let mut reader = ZlibDecoder::new(block);
                inflate_values(path, &mut reader, inflated, format, count, &mut out)?;
                expect_end(path, &mut reader, inflated)?;
            }
            at = end;
        }
        Ok(out)
    }
}

/// The blocks (count, size, size of the last or 0 when full) must hold exactly `bytes` bytes,
/// and whole values per block so that no value straddles two.
fn check_blocks(
    path: &Path,
    (blocks, block, last): (u64, u64, u64),
    value: u64,
    bytes: u64,
) -> Result<(), VolumeError> {
    let last_size = if last == 0 { block } else { last };
    let total = match blocks {
        0 => Some(0),
        n => (n - 1)
            .checked_mul(block)
            .and_then(|b| b.checked_add(last_size)),
    };
    if total != Some(bytes) || !block.is_multiple_of(value) || last > block {
        let message = format!(
            "{blocks} compressed blocks of {block} bytes (last {last}) do not hold the \
             {bytes} bytes of the extent"
        );
        return Err(header_error(path, message));
    }
    Ok(())
}

/// Bytes of a compression header with `blocks` blocks: count, block size, last size, sizes.
fn header_len(word: usize, blocks: u64) -> Option<usize> {
    usize::try_from(blocks)
        .ok()?
        .checked_add(3)?
        .checked_mul(word)
}

/// The text with its whitespace (line breaks, indentation) left out.
fn without_whitespace(text: &[u8]) -> Vec<u8> {
    text.iter()
        .copied()
        .filter(|b| !b.is_ascii_whitespace())
        .collect()
}

/// Base64 characters encoding `bytes` bytes, padded.
fn encoded_len(bytes: usize) -> usize {
    bytes.div_ceil(3) * 4
}

fn base64(path: &Path, text: &[u8]) -> Result<Vec<u8>, VolumeError> {
    let text: Vec<u8> = text
        .iter()
        .copied()
        .filter(|b| !b.is_ascii_whitespace())
        .collect();
    BASE64
        .decode(&text)
        .map_err(|e| header_error(path, format!("bad base64 data: {e}")))
}

#[cfg(test)]
mod tests;
