//! Reading a DICOM file's header: opening it (with the size checks a deflated file needs), its
//! slices' positions, orientations, spacings and rescales (per frame for multi-frame objects).

use super::*;

/// Opens a DICOM file, with or without its preamble; a bare data set is read with the
/// transfer syntax its bytes show and given a file meta group.
pub(super) fn open(path: &Path) -> Result<DefaultDicomObject, String> {
    check_deflated_size(path)?;
    let parsed = OpenFileOptions::new().open_file(path);
    let error = match parsed {
        Ok(obj) => return Ok(obj),
        Err(e) => describe("cannot parse DICOM", &e),
    };
    let mut head = Vec::with_capacity(SNIFF_LEN);
    crate::input::open_regular(path)
        .and_then(|f| f.take(SNIFF_LEN as u64).read_to_end(&mut head))
        .map_err(|e| format!("cannot read: {e}"))?;
    let Some(ts) = bare_data_set(&head) else {
        return Err(error);
    };
    let syntax = TransferSyntaxRegistry
        .get(ts)
        .ok_or_else(|| format!("no transfer syntax {ts} in this build"))?;
    let file = crate::input::open_regular(path).map_err(|e| format!("cannot read: {e}"))?;
    let data = InMemDicomObject::read_dataset_with_ts(BufReader::new(file), syntax)
        .map_err(|e| describe("cannot parse a DICOM data set without meta group", &e))?;
    // The SOP identifiers are the data set's own when it has them (with_meta takes those).
    let meta = FileMetaTableBuilder::new()
        .transfer_syntax(ts)
        .media_storage_sop_class_uid(uids::SECONDARY_CAPTURE_IMAGE_STORAGE)
        .media_storage_sop_instance_uid("2.25.0");
    data.with_meta(meta)
        .map_err(|e| describe("cannot give the data set a meta group", &e))
}

/// The Deflated Explicit VR Little Endian transfer syntax.
pub(super) const DEFLATED: &str = "1.2.840.10008.1.2.1.99";

/// Refuses a deflated data set that inflates to more than [`MAX_EXPANSION`] times its file
/// (or [`ALWAYS_ALLOWED_BYTES`]), counted while inflating into nothing: the DICOM reader
/// inflates a deflated data set whole into memory, so a small file could otherwise take
/// gigabytes before any size is checked. No slice of such a file could be loaded anyway
/// ([`allocate`] applies the same bound to the volume).
pub(super) fn check_deflated_size(path: &Path) -> Result<(), String> {
    let mut file = crate::input::open_regular(path).map_err(|e| format!("cannot read: {e}"))?;
    let file_len = file
        .metadata()
        .map_err(|e| format!("cannot read: {e}"))?
        .len();
    let mut head = Vec::with_capacity(SNIFF_LEN);
    (&mut file)
        .take(SNIFF_LEN as u64)
        .read_to_end(&mut head)
        .map_err(|e| format!("cannot read: {e}"))?;
    // The meta group: its length (0002,0000) right after the magic, then its elements,
    // explicit VR little endian; the transfer syntax UID is (0002,0010).
    let group = PREAMBLE_LEN + 4;
    let Some(len) = head
        .get(group..group + 12)
        .filter(|e| e[..6] == [2, 0, 0, 0, b'U', b'L'])
        .map(|e| u64::from(u32::from_le_bytes([e[8], e[9], e[10], e[11]])))
    else {
        return Ok(());
    };
    let start = group as u64 + 12;
    let meta = head.get(start as usize..(start + len).min(head.len() as u64) as usize);
    let deflated = meta.is_some_and(|m| {
        m.windows(6)
            .position(|w| w == [2, 0, 0x10, 0, b'U', b'I'])
            .and_then(|at| {
                let n = usize::from(u16::from_le_bytes([*m.get(at + 6)?, *m.get(at + 7)?]));
                m.get(at + 8..at + 8 + n)
            })
            .is_some_and(|uid| {
                // UIDs are padded to an even length with a NUL.
                let uid = uid.strip_suffix(&[0]).unwrap_or(uid);
                uid.trim_ascii() == DEFLATED.as_bytes()
            })
    });
    if !deflated {
        return Ok(());
    }
    let cap = file_len
        .saturating_mul(MAX_EXPANSION)
        .max(ALWAYS_ALLOWED_BYTES);
    std::io::Seek::seek(&mut file, std::io::SeekFrom::Start(start + len))
        .map_err(|e| format!("cannot read: {e}"))?;
    let mut inflated = flate2::read::DeflateDecoder::new(BufReader::new(file)).take(cap + 1);
    let n = std::io::copy(&mut inflated, &mut std::io::sink())
        .map_err(|e| format!("the deflated data set cannot be inflated: {e}"))?;
    if n > cap {
        return Err(format!(
            "the deflated data set inflates to more than {cap} bytes, {MAX_EXPANSION} times \
             its {file_len}-byte file: refused before reading it"
        ));
    }
    Ok(())
}

/// The image in a DICOM file, or `None` for a file without pixel data. A file that cannot be
/// parsed is an error here, since its series is unknown; one that parses but cannot be a slice
/// only matters if its series is the one loaded.
pub(super) fn read_image(path: &Path) -> Result<Option<Image>, VolumeError> {
    let file_len = fs::metadata(path).map_err(io_error(path))?.len();
    guarded(path, || {
        let obj = open(path)?;
        if obj.get(tags::PIXEL_DATA).is_none() {
            return Ok(None);
        }
        let text = |tag| optional_text(&obj, tag).filter(|t| !t.is_empty());
        let slices = slice_headers(&obj, path, file_len).map_err(|m| dicom_error(path, m));
        Ok(Some(Image {
            path: path.into(),
            series: text(tags::SERIES_INSTANCE_UID).unwrap_or_default(),
            instance: text(tags::SOP_INSTANCE_UID).unwrap_or_default(),
            tags: SeriesTags {
                number: text(tags::SERIES_NUMBER),
                description: text(tags::SERIES_DESCRIPTION),
                modality: text(tags::MODALITY),
            },
            slices,
        }))
    })
}

/// The first item of sequence `tag` in `obj`.
pub(super) fn first_item(obj: &InMemDicomObject, tag: Tag) -> Option<&InMemDicomObject> {
    obj.get(tag)?.items()?.first()
}

/// Where a frame's functional group attributes are: its own item of the per-frame
/// sequence, then the shared item.
pub(super) struct Groups<'a> {
    own: Option<&'a InMemDicomObject>,
    shared: Option<&'a InMemDicomObject>,
}

impl<'a> Groups<'a> {
    /// The item of macro sequence `sequence` holding this frame's attributes.
    fn macro_item(&self, sequence: Tag) -> Option<&'a InMemDicomObject> {
        self.own
            .and_then(|o| first_item(o, sequence))
            .or_else(|| self.shared.and_then(|s| first_item(s, sequence)))
    }
}

/// The slices of an image: one for a single-frame image, one per frame otherwise.
pub(super) fn slice_headers(
    obj: &DefaultDicomObject,
    path: &Path,
    file_len: u64,
) -> Result<Vec<SliceHeader>, String> {
    let frames = match optional_text(obj, tags::NUMBER_OF_FRAMES).as_deref() {
        None | Some("") => 1,
        Some(text) => text
            .parse::<u32>()
            .ok()
            .filter(|n| (1..=MAX_FRAMES).contains(n))
            .ok_or_else(|| format!("NumberOfFrames {text:?} is not 1 to {MAX_FRAMES}"))?,
    };
    let rows = unsigned(obj, tags::ROWS, "Rows")?;
    let columns = unsigned(obj, tags::COLUMNS, "Columns")?;
    let bits = unsigned(obj, tags::BITS_ALLOCATED, "BitsAllocated").ok();
    if bits == Some(1) {
        return Err(
            "1-bit pixels (a binary segmentation or overlay) are not read as a volume".into(),
        );
    }
    let signed = unsigned(obj, tags::PIXEL_REPRESENTATION, "PixelRepresentation").ok() == Some(1);
    let stored = match (bits, signed) {
        (Some(8), false) => Some(ScalarType::U8),
        (Some(8), true) => Some(ScalarType::I8),
        (Some(16), false) => Some(ScalarType::U16),
        (Some(16), true) => Some(ScalarType::I16),
        (Some(32), false) => Some(ScalarType::U32),
        (Some(32), true) => Some(ScalarType::I32),
        _ => None,
    };
    let (top_slope, top_intercept) = rescale_of(obj)?;
    let base = SliceHeader {
        path: path.into(),
        frame: None,
        rows,
        columns,
        row_dir: DVec3::X,
        col_dir: DVec3::Y,
        position: DVec3::ZERO,
        pixel_spacing: [1.0; 2],
        slice_thickness: None,
        file_len: file_len / u64::from(frames),
        stored,
        slope: top_slope,
        intercept: top_intercept,
        unplaced: false,
    };
    let per_frame = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items());
    let offsets = obj.get(tags::GRID_FRAME_OFFSET_VECTOR);
    if frames == 1 && per_frame.is_none() {
        if obj.get(tags::IMAGE_POSITION_PATIENT).is_none()
            && obj.get(tags::IMAGE_ORIENTATION_PATIENT).is_none()
        {
            // A projection or a secondary capture: no place in the patient. Alone it is
            // placed as ITK places it; in a stack it is refused (see build_volume).
            let spacing = floats::<2>(obj, tags::PIXEL_SPACING, "PixelSpacing")
                .or_else(|_| floats::<2>(obj, tags::IMAGER_PIXEL_SPACING, "ImagerPixelSpacing"))
                .unwrap_or([1.0, 1.0]);
            if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(format!("PixelSpacing {spacing:?} is not positive"));
            }
            return Ok(vec![SliceHeader {
                pixel_spacing: spacing,
                unplaced: true,
                ..base
            }]);
        }
        return Ok(vec![plane_of(obj, obj, obj, base)?]);
    }
    if let Some(items) = per_frame {
        // Enhanced images: every frame's geometry in its functional groups.
        if items.len() != frames as usize {
            return Err(format!(
                "{} per-frame functional groups for {frames} frames",
                items.len()
            ));
        }
        let shared = first_item(obj, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE);
        return items
            .iter()
            .enumerate()
            .map(|(k, item)| {
                let groups = Groups {
                    own: Some(item),
                    shared,
                };
                let missing = |what: &str| format!("frame {}: no {what}", k + 1);
                let position = groups
                    .macro_item(tags::PLANE_POSITION_SEQUENCE)
                    .ok_or_else(|| missing("PlanePositionSequence"))?;
                let orientation = groups
                    .macro_item(tags::PLANE_ORIENTATION_SEQUENCE)
                    .ok_or_else(|| missing("PlaneOrientationSequence"))?;
                let measures = groups
                    .macro_item(tags::PIXEL_MEASURES_SEQUENCE)
                    .ok_or_else(|| missing("PixelMeasuresSequence"))?;
                let mut slice = SliceHeader {
                    frame: Some(k as u32),
                    ..base.clone()
                };
                if let Some(transform) =
                    groups.macro_item(tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE)
                {
                    (slice.slope, slice.intercept) = rescale_of(transform)?;
                }
                plane_of(position, orientation, measures, slice)
                    .map_err(|m| format!("frame {}: {m}", k + 1))
            })
            .collect();
    }
    let Some(offsets) = offsets else {
        return Err(format!(
            "{frames} frames without per-frame positions (no functional groups or \
             GridFrameOffsetVector): not a volume"
        ));
    };
    // A grid of frames along the normal (RT dose).
    let offsets = numbers_of(offsets, "GridFrameOffsetVector")?;
    if offsets.len() != frames as usize || offsets.iter().any(|o| !o.is_finite()) {
        return Err(format!(
            "GridFrameOffsetVector has {} finite values for {frames} frames",
            offsets.len()
        ));
    }
    let mut first = plane_of(obj, obj, obj, base)?;
    if let Some(scaling) = obj.get(tags::DOSE_GRID_SCALING) {
        let [scale] = floats_of::<1>(scaling, "DoseGridScaling")?;
        first.slope *= scale;
        first.intercept *= scale;
    }
    let normal = first.row_dir.cross(first.col_dir);
    Ok((0..frames)
        .map(|k| SliceHeader {
            frame: Some(k),
            position: first.position + normal * (offsets[k as usize] - offsets[0]),
            ..first.clone()
        })
        .collect())
}

/// `slice` with its position, orientation and spacing from the three objects that hold
/// them (the image itself, or a frame's functional group items).
pub(super) fn plane_of(
    position: &InMemDicomObject,
    orientation: &InMemDicomObject,
    measures: &InMemDicomObject,
    slice: SliceHeader,
) -> Result<SliceHeader, String> {
    let iop = floats::<6>(
        orientation,
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
    )?;
    let (row_dir, col_dir) = unit_axes(iop)?;
    let ipp = floats::<3>(
        position,
        tags::IMAGE_POSITION_PATIENT,
        "ImagePositionPatient",
    )?;
    let pixel_spacing = floats::<2>(measures, tags::PIXEL_SPACING, "PixelSpacing")?;
    if pixel_spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(format!("PixelSpacing {pixel_spacing:?} is not positive"));
    }
    // A lone slice's depth: SpacingBetweenSlices, else SliceThickness.
    let slice_thickness = floats::<1>(
        measures,
        tags::SPACING_BETWEEN_SLICES,
        "SpacingBetweenSlices",
    )
    .or_else(|_| floats::<1>(measures, tags::SLICE_THICKNESS, "SliceThickness"))
    .ok()
    .map(|[t]| t)
    .filter(|t| t.is_finite() && *t > 0.0);
    Ok(SliceHeader {
        row_dir,
        col_dir,
        position: DVec3::from(ipp),
        pixel_spacing,
        slice_thickness,
        ..slice
    })
}

/// RescaleSlope and RescaleIntercept of `obj` (1 and 0 when absent), which must be finite.
pub(super) fn rescale_of(obj: &InMemDicomObject) -> Result<(f64, f64), String> {
    let get = |tag, name, default| match obj.get(tag) {
        Some(e) => floats_of::<1>(e, name).map(|[v]| v),
        None => Ok(default),
    };
    Ok((
        get(tags::RESCALE_SLOPE, "RescaleSlope", 1.0)?,
        get(tags::RESCALE_INTERCEPT, "RescaleIntercept", 0.0)?,
    ))
}

/// A text attribute without DICOM's space or NUL padding; `None` when absent or unreadable.
pub(super) fn optional_text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let value = obj.get(tag)?.to_str().ok()?;
    Some(value.trim_matches(['\0', ' ']).to_owned())
}

pub(super) fn unsigned(obj: &InMemDicomObject, tag: Tag, name: &str) -> Result<u16, String> {
    let element = obj.get(tag).ok_or_else(|| format!("no {name}"))?;
    match element.to_int::<u16>() {
        Ok(0) | Err(_) => Err(format!("{name} is not a positive 16-bit number")),
        Ok(n) => Ok(n),
    }
}

/// Exactly `N` finite numbers from a decimal-string attribute.
pub(super) fn floats<const N: usize>(
    obj: &InMemDicomObject,
    tag: Tag,
    name: &str,
) -> Result<[f64; N], String> {
    let element = obj.get(tag).ok_or_else(|| format!("no {name}"))?;
    floats_of(element, name)
}

/// The numbers of an element. An element whose VR is UN (as some writers store attributes
/// they do not know) holds its decimal strings as bytes, which are read as text.
pub(super) fn numbers_of(
    element: &dicom_object::mem::InMemElement,
    name: &str,
) -> Result<Vec<f64>, String> {
    if element.vr() != VR::UN {
        return element
            .to_multi_float64()
            .map_err(|e| format!("{name} is not numeric: {e}"));
    }
    let bytes = element
        .to_bytes()
        .map_err(|e| format!("{name} is not numeric: {e}"))?;
    let text = std::str::from_utf8(&bytes).map_err(|_| format!("{name} is not numeric text"))?;
    text.trim_matches(['\0', ' '])
        .split('\\')
        .map(|word| {
            word.trim()
                .parse::<f64>()
                .map_err(|_| format!("{name} holds {word:?}, not a number"))
        })
        .collect()
}

/// Exactly `N` finite numbers from an element.
pub(super) fn floats_of<const N: usize>(
    element: &dicom_object::mem::InMemElement,
    name: &str,
) -> Result<[f64; N], String> {
    let values = numbers_of(element, name)?;
    let array: [f64; N] = values
        .as_slice()
        .try_into()
        .map_err(|_| format!("{name} has {} values instead of {N}", values.len()))?;
    if array.iter().all(|v| v.is_finite()) {
        Ok(array)
    } else {
        Err(format!("{name} {array:?} is not finite"))
    }
}

/// The row and column directions of ImageOrientationPatient, which must be (close to) unit
/// length and perpendicular; they are renormalised to remove the rounding of their DS strings.
pub(super) fn unit_axes(orientation: [f64; 6]) -> Result<(DVec3, DVec3), String> {
    let row = DVec3::new(orientation[0], orientation[1], orientation[2]);
    let col = DVec3::new(orientation[3], orientation[4], orientation[5]);
    let unit = |v: DVec3| (v.length() - 1.0).abs() < 1e-3;
    if !unit(row) || !unit(col) || row.dot(col).abs() > 1e-3 {
        return Err(format!(
            "ImageOrientationPatient {orientation:?} is not two perpendicular unit vectors"
        ));
    }
    Ok((row.normalize(), col.normalize()))
}
