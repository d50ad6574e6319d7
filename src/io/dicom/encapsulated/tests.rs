use super::*;

#[test]
fn fragments_are_assigned_to_frames() {
    const JPEG: &str = "1.2.840.10008.1.2.4.70";
    let soi: &[u8] = &[0xFF, 0xD8, 1, 2];
    let soc: &[u8] = &[0xFF, 0x4F, 0xFF, 0x51, 9, 9];
    let more: &[u8] = &[7, 7, 7, 7, 7, 7];
    // One fragment per frame, and every fragment for one frame.
    assert_eq!(
        frame_fragments(JPEG, 2, &[soi, soi], &[]),
        Some(vec![0..1, 1..2])
    );
    assert_eq!(
        frame_fragments(JPEG, 1, &[soi, more, more], &[]),
        Some(std::iter::once(0..3).collect::<Vec<_>>())
    );
    // The Basic Offset Table: frame 1 starts at the third fragment (4 + 8 + 6 + 8 bytes in).
    assert_eq!(
        frame_fragments(JPEG, 2, &[soi, more, soi, more, more], &[0, 26]),
        Some(vec![0..2, 2..5])
    );
    // A table that points between fragments is not used; the codestream starts are.
    assert_eq!(
        frame_fragments(JPEG, 2, &[soi, more, soi, more, more], &[0, 25]),
        Some(vec![0..2, 2..5])
    );
    assert_eq!(
        frame_fragments(JPEG, 3, &[soc, more, soc, soc, more], &[]),
        Some(vec![0..2, 2..3, 3..5])
    );
    // Neither says: the caller decodes the whole pixel data at once.
    assert_eq!(frame_fragments(JPEG, 2, &[soi, more, more], &[]), None);
    assert_eq!(frame_fragments(JPEG, 3, &[soi, soi], &[]), None);
    assert_eq!(frame_fragments(JPEG, 1, &[], &[]), None);
    // RLE: one fragment per frame, extra fragments ignored, too few refused.
    assert_eq!(
        frame_fragments(RLE_LOSSLESS, 2, &[more, more, more], &[]),
        Some(vec![0..1, 1..2])
    );
    assert_eq!(frame_fragments(RLE_LOSSLESS, 3, &[more, more], &[]), None);
}

#[test]
fn packbits() {
    let mut out = Vec::new();
    // literal run of 2, repeat 3 x 7, no-op, literal 1
    unpack_bits(&[1, 10, 11, (-2i8) as u8, 7, 0x80, 0, 42], 100, &mut out);
    assert_eq!(out, vec![10, 11, 7, 7, 7, 42]);
    out.clear();
    unpack_bits(&[(-127i8) as u8, 1], 5, &mut out);
    assert_eq!(out.len(), 5);
    out.clear();
    unpack_bits(&[5, 1], 10, &mut out);
    assert_eq!(out, vec![1]);
}
