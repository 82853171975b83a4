//! 12-bit JPEG (DICOM's JPEG Extended, process 4: 1.2.840.10008.1.2.4.51), which the pure-Rust
//! JPEG decoders that dicom-pixeldata uses do not read (they stop at 8-bit DCT data). CT
//! scanners wrote it for years, so it is decoded here through libjpeg-turbo 3's TurboJPEG API
//! (`turbojpeg-sys`, built from its bundled source), whose `tj3Decompress12` reads 9- to 12-bit
//! DCT data. Only the calls are written here; the decoding is libjpeg-turbo's.

use std::ffi::CStr;

use turbojpeg_sys as tj;

/// A TurboJPEG decompressor, destroyed when dropped.
struct Handle(tj::tjhandle);

impl Drop for Handle {
    #[allow(unsafe_code)]
    fn drop(&mut self) {
        // SAFETY: the handle came from tj3Init and is destroyed once.
        unsafe { tj::tj3Destroy(self.0) }
    }
}

impl Handle {
    #[allow(unsafe_code)]
    fn new() -> Result<Self, String> {
        // SAFETY: tj3Init has no preconditions; a null result is checked.
        let handle = unsafe { tj::tj3Init(tj::TJINIT_TJINIT_DECOMPRESS as i32) };
        if handle.is_null() {
            return Err("the JPEG decoder could not start".into());
        }
        Ok(Self(handle))
    }

    #[allow(unsafe_code)]
    fn error(&self) -> String {
        // SAFETY: tj3GetErrorStr returns a NUL-terminated string owned by the handle, read
        // here before any other call on it.
        let text = unsafe { CStr::from_ptr(tj::tj3GetErrorStr(self.0)) };
        text.to_string_lossy().into_owned()
    }

    #[allow(unsafe_code)]
    fn get(&self, param: tj::TJPARAM) -> i32 {
        // SAFETY: a valid handle and one of TurboJPEG's parameter numbers.
        unsafe { tj::tj3Get(self.0, param as i32) }
    }
}

/// Decodes one 12-bit greyscale JPEG frame of `columns` x `rows` samples, appending them to
/// `out` as little-endian u16 (the value in the low 12 bits).
#[allow(unsafe_code)]
pub(super) fn decode_frame(
    jpeg: &[u8],
    columns: usize,
    rows: usize,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let handle = Handle::new()?;
    // SAFETY: the buffer and its length describe `jpeg`, which outlives the call.
    let read =
        unsafe { tj::tj3DecompressHeader(handle.0, jpeg.as_ptr(), jpeg.len() as tj::size_t) };
    if read != 0 {
        return Err(format!("JPEG header: {}", handle.error()));
    }
    let (width, height) = (
        handle.get(tj::TJPARAM_TJPARAM_JPEGWIDTH),
        handle.get(tj::TJPARAM_TJPARAM_JPEGHEIGHT),
    );
    if usize::try_from(width) != Ok(columns) || usize::try_from(height) != Ok(rows) {
        return Err(format!(
            "the JPEG image is {width}x{height}, the header says {columns}x{rows}"
        ));
    }
    let precision = handle.get(tj::TJPARAM_TJPARAM_PRECISION);
    if !(9..=12).contains(&precision) || handle.get(tj::TJPARAM_TJPARAM_LOSSLESS) == 1 {
        return Err(format!(
            "a {precision}-bit {}JPEG frame where 12-bit DCT data were expected",
            if handle.get(tj::TJPARAM_TJPARAM_LOSSLESS) == 1 {
                "lossless "
            } else {
                ""
            }
        ));
    }
    let mut samples = vec![0i16; columns * rows];
    // SAFETY: `samples` holds width x height greyscale samples at a pitch of `width`, as the
    // header just read says the image has, and outlives the call.
    let done = unsafe {
        tj::tj3Decompress12(
            handle.0,
            jpeg.as_ptr(),
            jpeg.len() as tj::size_t,
            samples.as_mut_ptr(),
            width,
            tj::TJPF_TJPF_GRAY,
        )
    };
    if done != 0 {
        // SAFETY: a valid handle.
        let code = unsafe { tj::tj3GetErrorCode(handle.0) };
        if code != tj::TJERR_TJERR_WARNING as i32 {
            return Err(format!("JPEG data: {}", handle.error()));
        }
        // A warning leaves a whole image (libjpeg's "Invalid SOS parameters for sequential
        // JPEG", which GDCM and so ITK also pass over): said, and read as they read it.
        eprintln!("note: 12-bit JPEG decoder warning: {}", handle.error());
    }
    out.reserve(samples.len() * 2);
    for s in samples {
        out.extend_from_slice(&(s as u16).to_le_bytes());
    }
    Ok(())
}
