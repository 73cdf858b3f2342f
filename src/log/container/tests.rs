//! Tests of [`super`] (container).

#[test]
fn a_record_past_its_chunks_end_is_reported() {
    // One whole record (opcode 5, 2 bytes), then one that claims 100 bytes of the 3 left.
    let mut data = vec![5u8];
    data.extend_from_slice(&2u64.to_le_bytes());
    data.extend_from_slice(&[7, 7]);
    data.push(5);
    data.extend_from_slice(&100u64.to_le_bytes());
    data.extend_from_slice(&[1, 2, 3]);
    let mut seen = Vec::new();
    let damage = for_each_record(&data, |op, body, _| seen.push((op, body.to_vec())));
    assert_eq!(seen, [(5, vec![7, 7])]);
    let damage = damage.unwrap();
    assert!(
        damage.contains("claims 100 bytes, past the chunk's end"),
        "{damage}"
    );
    // A clean chunk reports nothing; a short tail does.
    assert_eq!(for_each_record(&data[..11], |_, _, _| {}), None);
    assert!(
        for_each_record(&data[..15], |_, _, _| {})
            .unwrap()
            .contains("too few")
    );
}
use super::*;

#[test]
fn crc32_known_value() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
}
