//! The protobuf wire format, as much of it as a Perfetto trace needs: varints, fixed64 values and
//! length-delimited fields (strings, nested messages).
//!
//! Hand-written rather than a crate: the maintained bindings (`perfetto_protos`, protobuf-codegen
//! and a vendored protoc; `perfetto-trace-proto`, prost-build and a protoc of the system's) compile
//! the whole of Perfetto's trace.proto, hundreds of messages, on every clean build of a
//! two-core machine, for the few dozen fields the export writes. The field numbers the export
//! uses are named, each with its message and field, in `super::field`; this module knows nothing
//! of Perfetto.

/// A wire type: how a field's value is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
enum WireType {
    Varint = 0,
    Fixed64 = 1,
    LengthDelimited = 2,
}

/// Appends `value` as a base-128 varint: seven bits a byte, low bits first, the top bit set on
/// every byte but the last.
pub fn varint(out: &mut Vec<u8>, mut value: u64) {
    while value >= 0x80 {
        out.push((value as u8) | 0x80);
        value >>= 7;
    }
    out.push(value as u8);
}

fn key(out: &mut Vec<u8>, field: u32, wire: WireType) {
    varint(out, (u64::from(field) << 3) | wire as u64);
}

/// An unsigned varint field (uint32, uint64, bool, an enum).
pub fn uint(out: &mut Vec<u8>, field: u32, value: u64) {
    key(out, field, WireType::Varint);
    varint(out, value);
}

/// A signed varint field (int32, int64): two's complement, so a negative value takes ten bytes.
pub fn int(out: &mut Vec<u8>, field: u32, value: i64) {
    uint(out, field, value as u64);
}

/// A fixed64 field, little-endian.
pub fn fixed64(out: &mut Vec<u8>, field: u32, value: u64) {
    key(out, field, WireType::Fixed64);
    out.extend_from_slice(&value.to_le_bytes());
}

/// A string or bytes field.
pub fn bytes(out: &mut Vec<u8>, field: u32, value: &[u8]) {
    key(out, field, WireType::LengthDelimited);
    varint(out, value.len() as u64);
    out.extend_from_slice(value);
}

/// A nested message: `body` writes its fields after the key, and its length is put before them.
/// The length is guessed to fit one byte (most messages here are shorter than 128 bytes) and the
/// body moved along when it does not.
pub fn message(out: &mut Vec<u8>, field: u32, body: impl FnOnce(&mut Vec<u8>)) {
    key(out, field, WireType::LengthDelimited);
    let at = out.len();
    out.push(0);
    body(out);
    let len = out.len() - at - 1;
    if len < 0x80 {
        out[at] = len as u8;
    } else {
        let mut prefix = Vec::with_capacity(10);
        varint(&mut prefix, len as u64);
        out.splice(at..=at, prefix);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encoded(f: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
        let mut out = vec![];
        f(&mut out);
        out
    }

    #[test]
    fn varints_are_seven_bits_a_byte_low_first() {
        assert_eq!(encoded(|o| varint(o, 0)), [0]);
        assert_eq!(encoded(|o| varint(o, 1)), [1]);
        assert_eq!(encoded(|o| varint(o, 127)), [0x7f]);
        assert_eq!(encoded(|o| varint(o, 128)), [0x80, 0x01]);
        // The protobuf documentation's example: 150 is 96 01.
        assert_eq!(encoded(|o| varint(o, 150)), [0x96, 0x01]);
        assert_eq!(encoded(|o| varint(o, u64::MAX)), [0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01]);
    }

    #[test]
    fn fields_carry_their_number_and_wire_type() {
        // Field 1 = 150: 08 96 01 (the documentation's example).
        assert_eq!(encoded(|o| uint(o, 1, 150)), [0x08, 0x96, 0x01]);
        // Field 2 = "testing": 12 07 74 65 73 74 69 6e 67.
        assert_eq!(encoded(|o| bytes(o, 2, b"testing")), b"\x12\x07testing");
        // A field number past 15 takes a two-byte key: 47 fixed64 is (47 << 3) | 1 = 377.
        assert_eq!(encoded(|o| fixed64(o, 47, 1)), [0xf9, 0x02, 1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(encoded(|o| int(o, 30, -1)).len(), 2 + 10, "a negative int64 takes ten bytes");
    }

    #[test]
    fn a_nested_message_is_its_length_then_its_fields() {
        // Field 3 holding field 1 = 150: 1a 03 08 96 01 (the documentation's example).
        assert_eq!(encoded(|o| message(o, 3, |o| uint(o, 1, 150))), [0x1a, 0x03, 0x08, 0x96, 0x01]);
        // A body of 201 bytes (a key, a two-byte length, 198 bytes) needs a two-byte length of
        // its own; the body is moved along, intact.
        let body: Vec<u8> = (0..198).map(|i| i as u8).collect();
        let out = encoded(|o| message(o, 1, |o| bytes(o, 2, &body)));
        assert_eq!(&out[..3], [0x0a, 0xc9, 0x01]);
        assert_eq!(&out[3..6], [0x12, 0xc6, 0x01]);
        assert_eq!(&out[6..], &body[..]);
        // Nested twice, each length right.
        let out = encoded(|o| message(o, 1, |o| message(o, 2, |o| uint(o, 3, 1))));
        assert_eq!(out, [0x0a, 0x04, 0x12, 0x02, 0x18, 0x01]);
    }
}
