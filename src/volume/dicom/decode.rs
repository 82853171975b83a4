//! Decoding the pixel data of a stack into the volume's values, in the type the modality's
//! rescale allows (i16, else f32), with the RLE decoder written here.

use super::*;

/// A type modality values are written in.
pub(super) trait Modality: Copy + Default + Send + Sync {
    /// The value, `None` where this type cannot hold it exactly.
    fn from_modality(v: f64) -> Option<Self>;
}

impl Modality for f32 {
    fn from_modality(v: f64) -> Option<Self> {
        Some(v as f32)
    }
}

impl Modality for i16 {
    fn from_modality(v: f64) -> Option<Self> {
        let fits = v.fract() == 0.0 && v >= f64::from(i16::MIN) && v <= f64::from(i16::MAX);
        fits.then_some(v as i16)
    }
}

/// The stack's modality values in `T`, each file decoded once and its frames written to their
/// places; `None` when a value does not fit `T`.
pub(super) fn decode_stack<T: Modality>(
    at: &Path,
    dims: [u32; 3],
    slices: &[SliceHeader],
) -> Result<Option<Vec<T>>, VolumeError> {
    let mut values = allocate::<T>(at, dims, slices)?;
    let plane = values.len() / slices.len();
    let mut by_file: BTreeMap<&Path, Vec<(usize, &SliceHeader)>> = BTreeMap::new();
    for (k, slice) in slices.iter().enumerate() {
        by_file.entry(&slice.path).or_default().push((k, slice));
    }
    let mut chunks: Vec<Option<&mut [T]>> = values.chunks_mut(plane).map(Some).collect();
    let work: Vec<(&Path, Vec<SliceOut<T>>)> = by_file
        .into_iter()
        .map(|(path, list)| {
            let outs = list
                .into_iter()
                .map(|(k, slice)| (slice, chunks[k].take().expect("one slice per place")))
                .collect();
            (path, outs)
        })
        .collect();
    let decoded: Vec<_> = work
        .into_par_iter()
        .map(|(path, outs)| decode_file(path, outs))
        .collect();
    let fits = first_error(decoded)?.into_iter().all(|fits| fits);
    Ok(fits.then_some(values))
}

/// The zeroed output, after checking its size against the grid limit and the files' bytes.
pub(super) fn allocate<T: Modality>(
    dir: &Path,
    dims: [u32; 3],
    slices: &[SliceHeader],
) -> Result<Vec<T>, VolumeError> {
    let held = if size_of::<T>() == 2 {
        ScalarType::I16
    } else {
        ScalarType::F32
    };
    let count = checked_voxels(dir, dims, held)?;
    let file_bytes: u64 = slices.iter().map(|s| s.file_len).sum::<u64>().max(1);
    let out_bytes = count.saturating_mul(size_of::<T>() as u64);
    if out_bytes
        > file_bytes
            .saturating_mul(MAX_EXPANSION)
            .max(ALWAYS_ALLOWED_BYTES)
    {
        let message = format!(
            "{dims:?} voxels would need {out_bytes} bytes, more than {MAX_EXPANSION} times the \
             {file_bytes} bytes of its files"
        );
        return Err(dicom_error(dir, message));
    }
    let too_big = || dicom_error(dir, format!("cannot allocate {out_bytes} bytes"));
    let count = usize::try_from(count).map_err(|_| too_big())?;
    let mut values = Vec::new();
    values.try_reserve_exact(count).map_err(|_| too_big())?;
    values.resize(count, T::default());
    Ok(values)
}

/// Decodes the pixel data of one file and writes each of its slices (frames) into its place
/// (Rows x Columns values, rows in order); `false` when a value does not fit `T`.
pub(super) fn decode_file<T: Modality>(
    path: &Path,
    outs: Vec<SliceOut<T>>,
) -> Result<bool, VolumeError> {
    guarded(path, || {
        let obj = open(path)?;
        let first = outs.first().map(|(s, _)| *s).ok_or("no slices")?;
        let frames = outs
            .iter()
            .filter_map(|(s, _)| s.frame)
            .max()
            .map_or(1, |k| k + 1);
        let voxels = usize::from(first.rows) * usize::from(first.columns);
        let decoded = obj.decode_pixel_data();
        let samples = match &decoded {
            Ok(pixels) => Samples::from_decoded(pixels, first, frames)?,
            Err(e) => {
                let message = describe("cannot decode pixel data", e);
                if obj.meta().transfer_syntax().trim_end_matches('\0') == RLE_LOSSLESS
                    && message.contains("BitsAllocated")
                {
                    // dicom-pixeldata's RLE decoder reads 8- and 16-bit samples only; RT dose
                    // grids store 32.
                    Samples::from_rle(&obj, voxels, frames)?
                } else if message.contains("SamplePrecision(12)") {
                    // jpeg-decoder reads 8-bit DCT data only; 12-bit goes to libjpeg-turbo.
                    let size = (usize::from(first.columns), usize::from(first.rows));
                    Samples::from_jpeg12(&obj, size, frames)?
                } else {
                    return Err(message);
                }
            }
        };
        let mut fits = true;
        for (slice, out) in outs {
            fits &= samples.modality_values(slice, out)?;
        }
        Ok(fits)
    })
}

/// The RLE Lossless transfer syntax.
pub(super) const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// One file's decoded samples, little-endian, frame after frame.
pub(super) struct Samples<'a> {
    data: std::borrow::Cow<'a, [u8]>,
    /// Bytes per sample.
    width: usize,
    /// Bits per sample that carry the value, from bit 0.
    stored: u32,
    signed: bool,
}

impl<'a> Samples<'a> {
    /// The samples `dicom-pixeldata` decoded, checked to hold at least `frames` frames of the
    /// slice's size with one grey sample per pixel.
    fn from_decoded(
        pixels: &'a DecodedPixelData,
        slice: &SliceHeader,
        frames: u32,
    ) -> Result<Self, String> {
        let size = (pixels.rows(), pixels.columns());
        let expected = (u32::from(slice.rows), u32::from(slice.columns));
        if size != expected || pixels.number_of_frames() < frames {
            return Err(format!(
                "decoded rows, columns {size:?} and {} frames differ from the header's \
                 {expected:?} and {frames}",
                pixels.number_of_frames()
            ));
        }
        if pixels.samples_per_pixel() != 1 || !pixels.photometric_interpretation().is_monochrome() {
            return Err("colour images are not supported".into());
        }
        let samples = Self::checked(
            pixels.data(),
            u32::from(pixels.bits_allocated()),
            u32::from(pixels.bits_stored()),
            u32::from(pixels.high_bit()),
            pixels.pixel_representation() == PixelRepresentation::Signed,
        )?;
        samples.check_len(size.0 as usize * size.1 as usize, frames)?;
        Ok(samples)
    }

    /// Samples from bytes and the bit layout, which must be one this loader reads.
    fn checked(
        data: impl Into<std::borrow::Cow<'a, [u8]>>,
        allocated: u32,
        stored: u32,
        high_bit: u32,
        signed: bool,
    ) -> Result<Self, String> {
        if !matches!(allocated, 8 | 16 | 32) || stored == 0 || stored > allocated {
            return Err(format!(
                "{stored} of {allocated} bits per sample is not supported"
            ));
        }
        if high_bit + 1 != stored {
            return Err("samples not aligned to bit 0 (HighBit != BitsStored - 1)".into());
        }
        Ok(Self {
            data: data.into(),
            width: allocated as usize / 8,
            stored,
            signed,
        })
    }

    /// The data must hold `frames` frames of `voxels` samples; more is padding (to an even
    /// length, or by the writer), which readers ignore.
    fn check_len(&self, voxels: usize, frames: u32) -> Result<(), String> {
        let size = self.data.len();
        let expected = voxels
            .checked_mul(self.width)
            .and_then(|b| b.checked_mul(frames as usize));
        if expected.is_none_or(|e| size < e) {
            return Err(format!(
                "decoded {size} bytes, but Rows x Columns x {frames} frame(s) x {} bytes is {}",
                self.width,
                voxels
                    .saturating_mul(self.width)
                    .saturating_mul(frames as usize)
            ));
        }
        Ok(())
    }

    /// Decodes RLE Lossless pixel data (DICOM PS3.5 annex G) of any sample width: each
    /// frame's fragment holds one PackBits segment per byte of the sample, most significant
    /// first. Written here for the 32-bit samples `dicom-pixeldata`'s decoder leaves out.
    fn from_rle(obj: &DefaultDicomObject, voxels: usize, frames: u32) -> Result<Self, String> {
        let allocated = u32::from(unsigned(obj, tags::BITS_ALLOCATED, "BitsAllocated")?);
        let stored = u32::from(unsigned(obj, tags::BITS_STORED, "BitsStored")?);
        let high_bit = obj
            .get(tags::HIGH_BIT)
            .and_then(|e| e.to_int::<u32>().ok())
            .unwrap_or(stored.saturating_sub(1));
        let samples_per_pixel = obj
            .get(tags::SAMPLES_PER_PIXEL)
            .and_then(|e| e.to_int::<u16>().ok())
            .unwrap_or(1);
        if samples_per_pixel != 1 {
            return Err("colour images are not supported".into());
        }
        let signed =
            unsigned(obj, tags::PIXEL_REPRESENTATION, "PixelRepresentation").ok() == Some(1);
        let width = allocated as usize / 8;
        let fragments = obj
            .get(tags::PIXEL_DATA)
            .and_then(|e| e.value().fragments())
            .ok_or("RLE pixel data without fragments")?;
        if fragments.len() < frames as usize {
            return Err(format!(
                "{} RLE fragments for {frames} frames",
                fragments.len()
            ));
        }
        let frame_bytes = voxels
            .checked_mul(width)
            .ok_or("the frame size overflows")?;
        let mut data = vec![0u8; frame_bytes * frames as usize];
        for (k, fragment) in fragments.iter().take(frames as usize).enumerate() {
            let frame = &mut data[k * frame_bytes..(k + 1) * frame_bytes];
            rle_frame(fragment, width, voxels, frame)
                .map_err(|m| format!("frame {}: {m}", k + 1))?;
        }
        Self::checked(data, allocated, stored, high_bit, signed)
    }

    /// The samples of 12-bit JPEG frames (see `volume::jpeg12`): one fragment a frame, or
    /// every fragment together for a file of one frame.
    #[cfg(feature = "codecs")]
    fn from_jpeg12(
        obj: &DefaultDicomObject,
        (columns, rows): (usize, usize),
        frames: u32,
    ) -> Result<Self, String> {
        let stored = u32::from(unsigned(obj, tags::BITS_STORED, "BitsStored")?);
        if !(9..=12).contains(&stored) {
            return Err(format!(
                "BitsStored {stored} in a 12-bit JPEG (Extended) file"
            ));
        }
        let signed =
            unsigned(obj, tags::PIXEL_REPRESENTATION, "PixelRepresentation").ok() == Some(1);
        let fragments = obj
            .get(tags::PIXEL_DATA)
            .and_then(|e| e.value().fragments())
            .ok_or("JPEG pixel data without fragments")?;
        let frames_data: Vec<std::borrow::Cow<'_, [u8]>> = if fragments.len() == frames as usize {
            fragments.iter().map(|f| f.as_slice().into()).collect()
        } else if frames == 1 {
            vec![fragments.concat().into()]
        } else {
            return Err(format!(
                "{} JPEG fragments for {frames} frames",
                fragments.len()
            ));
        };
        let mut data = Vec::new();
        for (k, frame) in frames_data.iter().enumerate() {
            super::super::jpeg12::decode_frame(frame, columns, rows, &mut data)
                .map_err(|m| format!("frame {}: {m}", k + 1))?;
        }
        Self::checked(data, 16, stored, stored - 1, signed)
    }

    /// 12-bit JPEG needs libjpeg-turbo, which this build leaves out.
    #[cfg(not(feature = "codecs"))]
    fn from_jpeg12(
        _obj: &DefaultDicomObject,
        _size: (usize, usize),
        _frames: u32,
    ) -> Result<Self, String> {
        Err(
            "12-bit JPEG needs the C codecs, which this build of splatscene leaves out \
             (the `codecs` feature)"
                .into(),
        )
    }

    /// Converts one slice's samples to modality values (HU for CT) with its rescale. Samples
    /// are read little-endian: the codecs write them so, and native pixel data come in the
    /// machine's order, which is little-endian on the x86-64 and aarch64 targets of this
    /// project.
    /// `false` (and the slice left part written) when a value does not fit `T`.
    fn modality_values<T: Modality>(
        &self,
        slice: &SliceHeader,
        out: &mut [T],
    ) -> Result<bool, String> {
        if !(slice.slope.is_finite() && slice.intercept.is_finite()) {
            return Err(format!(
                "rescale slope {} or intercept {} is not finite",
                slice.slope, slice.intercept
            ));
        }
        // The stored range's ends, rescaled, must be f32 numbers: a slope that takes a sample
        // to infinity is refused here, not drawn as infinite values.
        let (lo, hi) = if self.signed {
            (
                -(2f64.powi(self.stored as i32 - 1)),
                2f64.powi(self.stored as i32 - 1) - 1.0,
            )
        } else {
            (0.0, 2f64.powi(self.stored as i32) - 1.0)
        };
        for end in [lo, hi] {
            let v = end * slice.slope + slice.intercept;
            if !(v.is_finite() && v.abs() <= f64::from(f32::MAX)) {
                return Err(format!(
                    "rescale slope {} and intercept {} take the stored value {end} to {v:e}, past what a 32-bit float holds",
                    slice.slope, slice.intercept
                ));
            }
        }
        let frame_bytes = out.len() * self.width;
        let start = slice.frame.unwrap_or(0) as usize * frame_bytes;
        let data = self
            .data
            .get(start..start + frame_bytes)
            .ok_or("the decoded data end before this frame")?;
        // Shifting the stored bits to the top and back drops any bits above them (old overlay
        // planes) and, for signed samples, extends the sign.
        let shift = 32 - self.stored;
        for (value, bytes) in out.iter_mut().zip(data.chunks_exact(self.width)) {
            let mut word = [0u8; 4];
            word[..self.width].copy_from_slice(bytes);
            let top = u32::from_le_bytes(word) << shift;
            let sample = if self.signed {
                f64::from((top as i32) >> shift)
            } else {
                f64::from(top >> shift)
            };
            match T::from_modality(sample * slice.slope + slice.intercept) {
                Some(v) => *value = v,
                None => return Ok(false),
            }
        }
        Ok(true)
    }
}

/// Decodes one RLE frame into `out` (`voxels` little-endian samples of `width` bytes).
pub(super) fn rle_frame(
    fragment: &[u8],
    width: usize,
    voxels: usize,
    out: &mut [u8],
) -> Result<(), String> {
    let word = |i: usize| -> Option<usize> {
        let b: [u8; 4] = fragment.get(4 * i..4 * i + 4)?.try_into().ok()?;
        Some(u32::from_le_bytes(b) as usize)
    };
    let segments = word(0).ok_or("no RLE header")?;
    if segments != width {
        return Err(format!("{segments} RLE segments for {width}-byte samples"));
    }
    for segment in 0..segments {
        let start = word(1 + segment).ok_or("short RLE header")?;
        let end = match segment + 1 < segments {
            true => word(2 + segment).ok_or("short RLE header")?,
            false => fragment.len(),
        };
        let coded = fragment
            .get(start..end)
            .ok_or("an RLE segment runs past its fragment")?;
        // Segment 0 holds the most significant bytes; little-endian puts them last.
        let byte = width - 1 - segment;
        let mut written = 0usize;
        let mut at = 0usize;
        let mut put = |value: u8, written: &mut usize| {
            if *written < voxels {
                out[*written * width + byte] = value;
            }
            *written += 1;
        };
        while at < coded.len() && written < voxels {
            let n = coded[at] as i8;
            at += 1;
            if n >= 0 {
                let run = coded
                    .get(at..at + n as usize + 1)
                    .ok_or("an RLE literal run past the segment")?;
                for &b in run {
                    put(b, &mut written);
                }
                at += n as usize + 1;
            } else if n != -128 {
                let b = *coded.get(at).ok_or("an RLE repeat past the segment")?;
                at += 1;
                for _ in 0..(1 - n as isize) {
                    put(b, &mut written);
                }
            }
        }
        if written < voxels {
            return Err(format!(
                "RLE segment {segment} decodes to {written} of {voxels} bytes"
            ));
        }
    }
    Ok(())
}
