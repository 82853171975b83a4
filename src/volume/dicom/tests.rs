use super::*;

#[test]
fn bare_data_sets_are_told_by_their_first_two_elements() {
    // (0008,0005) CS "ISO_IR 100" then (0008,0008): explicit VR little endian.
    let mut explicit = vec![0x08, 0x00, 0x05, 0x00, b'C', b'S', 10, 0];
    explicit.extend(b"ISO_IR 100");
    explicit.extend([0x08, 0x00, 0x08, 0x00]);
    assert_eq!(
        bare_data_set(&explicit),
        Some(uids::EXPLICIT_VR_LITTLE_ENDIAN)
    );
    // The same implicit: a 4-byte length after the tag.
    let mut implicit = vec![0x08, 0x00, 0x05, 0x00, 10, 0, 0, 0];
    implicit.extend(b"ISO_IR 100");
    implicit.extend([0x08, 0x00, 0x08, 0x00]);
    assert_eq!(
        bare_data_set(&implicit),
        Some(uids::IMPLICIT_VR_LITTLE_ENDIAN)
    );
    // Big endian, explicit VR.
    let mut big = vec![0x00, 0x08, 0x00, 0x05, b'C', b'S', 0, 10];
    big.extend(b"ISO_IR 100");
    big.extend([0x00, 0x08, 0x00, 0x08]);
    assert_eq!(bare_data_set(&big), Some("1.2.840.10008.1.2.2"));
    assert!(is_dicom(&big));
    // Raw samples that happen to start with 8 do not pass: the second element is not
    // where the first one's length puts it.
    let raw: Vec<u8> = [8u16, 0, 5, 0, 300, 301, 302, 303, 304]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    assert_eq!(bare_data_set(&raw), None);
    assert!(!is_dicom(&raw));
    assert!(!is_dicom(&explicit[..12]));
}

#[test]
fn sixteen_bit_modality_values_are_exact_integers_in_range() {
    assert_eq!(i16::from_modality(-1024.0), Some(-1024));
    assert_eq!(i16::from_modality(32767.0), Some(i16::MAX));
    assert_eq!(i16::from_modality(-32768.0), Some(i16::MIN));
    for wide in [32768.0, -32769.0, 0.5, f64::NAN, f64::INFINITY] {
        assert_eq!(i16::from_modality(wide), None, "{wide}");
    }
    assert_eq!(f32::from_modality(0.25), Some(0.25));
}

#[test]
fn rle_segments_decode_to_little_endian_samples() {
    // Two 32-bit samples, 0x01020304 and 0x0A0B0C0D: four segments, most significant
    // byte first, each a literal run of 2 (or a repeat run).
    let segments: [&[u8]; 4] = [
        &[1, 0x01, 0x0A],
        &[1, 0x02, 0x0B],
        &[1, 0x03, 0x0C],
        &[0xff, 0x04],
    ];
    let mut fragment = vec![0u8; 64];
    fragment[..4].copy_from_slice(&4u32.to_le_bytes());
    for (i, segment) in segments.iter().enumerate() {
        let at = fragment.len() as u32;
        fragment[4 + 4 * i..8 + 4 * i].copy_from_slice(&at.to_le_bytes());
        fragment.extend(*segment);
    }
    let mut out = [0u8; 8];
    rle_frame(&fragment, 4, 2, &mut out).unwrap();
    // The last segment repeats 0x04 twice.
    assert_eq!(u32::from_le_bytes(out[..4].try_into().unwrap()), 0x01020304);
    assert_eq!(u32::from_le_bytes(out[4..].try_into().unwrap()), 0x0A0B0C04);
    let err = rle_frame(&fragment[..66], 4, 2, &mut out).unwrap_err();
    assert!(err.contains("RLE"), "{err}");
    let err = rle_frame(&fragment, 2, 2, &mut [0u8; 4]).unwrap_err();
    assert!(err.contains("4 RLE segments for 2-byte samples"), "{err}");
}
