//! Numbers as text, written straight into a byte buffer: the CSV files' `{}` and the recording's
//! JSON numbers, byte for byte what `format!("{x}")` and serde_json write, without the formatting
//! machinery or an allocation per value (a run writes tens of them per loop).

/// An integer as `{}` writes it (and as JSON does).
pub fn push_int(buf: &mut Vec<u8>, value: impl itoa::Integer) {
    buf.extend_from_slice(itoa::Buffer::new().format(value).as_bytes());
}

/// A float as JSON holds it, as serde_json writes it: its shortest round-trip digits (zmij, the
/// formatter serde_json uses), and a non-finite value, which JSON cannot hold, as null.
pub fn push_json_f64(buf: &mut Vec<u8>, value: f64) {
    if value.is_finite() {
        buf.extend_from_slice(zmij::Buffer::new().format_finite(value).as_bytes());
    } else {
        buf.extend_from_slice(b"null");
    }
}

/// A float as `{}` writes it: the shortest digits that read back as the same value, never with
/// an exponent (`1e-7` is `0.0000001`), no `.0` on a whole number, `-0` for negative zero, and
/// `NaN`, `inf`, `-inf`.
///
/// zmij finds the shortest round-trip digits, as `{}` does, and lays them out as `{}` does from
/// 1e-5 to 1e16 but for a whole number's `.0`; elsewhere (`1e-7`, `1.5e+300`) the layout is redone
/// here. Only where two shortest candidates lie exactly as close to the value do the two choose
/// differently (zmij the even one, `{}` the upper one): such a value is found exactly and
/// written by `{}` itself.
pub fn push_f64(buf: &mut Vec<u8>, value: f64) {
    if !value.is_finite() || may_be_a_tie(value) {
        use std::io::Write as _;
        write!(buf, "{value}").expect("a Vec takes every byte");
        return;
    }
    let mut shortest = zmij::Buffer::new();
    let text = shortest.format_finite(value).as_bytes();
    if !text.contains(&b'e') {
        buf.extend_from_slice(text.strip_suffix(b".0").unwrap_or(text));
        return;
    }
    let (negative, text) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, text),
    };
    if negative {
        buf.push(b'-');
    }
    let (digits, point) = Digits::of(text);
    let digits = digits.as_slice();
    match point {
        // All of them after the point: 0.00ddd.
        ..=0 => {
            buf.extend_from_slice(b"0.");
            buf.resize(buf.len() + point.unsigned_abs() as usize, b'0');
            buf.extend_from_slice(digits);
        }
        // A whole number: ddd000.
        p if p as usize >= digits.len() => {
            buf.extend_from_slice(digits);
            buf.resize(buf.len() + p as usize - digits.len(), b'0');
        }
        p => {
            buf.extend_from_slice(&digits[..p as usize]);
            buf.push(b'.');
            buf.extend_from_slice(&digits[p as usize..]);
        }
    }
}

/// Whether `value` may lie exactly halfway between its two shortest candidates. It can only where
/// its exact decimal expansion is at most 18 digits long and ends in a 5 after the point:
/// value = m·2^-s with m odd and s > 0 is m·5^s / 10^s, whose digits are those of m·5^s. (A
/// whole number's neighbours are too far apart for a tie.) So most values are let through by a
/// shift and a compare; the few that are not (0.5, 0.25, 2.375, …) go to `{}`.
fn may_be_a_tie(value: f64) -> bool {
    let bits = value.to_bits() & !(1 << 63);
    let (exponent, fraction) = ((bits >> 52) as i32, bits & ((1 << 52) - 1));
    let (mantissa, e) = match exponent {
        0 => (fraction, -1074),
        _ => (fraction | 1 << 52, exponent - 1075),
    };
    if mantissa == 0 {
        return false;
    }
    let twos = mantissa.trailing_zeros() as i32;
    let fives = -(e + twos);
    // 5^26 > 10^18.
    if !(1..=25).contains(&fives) {
        return false;
    }
    u128::from(mantissa >> twos) * 5u128.pow(fives as u32) < 10u128.pow(18)
}

/// A decimal number's significant digits, without leading or trailing zeros, and where its point
/// lies: the value is 0.DIGITS × 10^point.
struct Digits {
    bytes: [u8; 24],
    len: usize,
}

impl Digits {
    /// Reads a positive number as zmij writes it with an exponent: `1.5e+300`, `5e-7`.
    fn of(text: &[u8]) -> (Self, i32) {
        let mut digits = Digits { bytes: [0; 24], len: 0 };
        let (mantissa, exponent) = match text.iter().position(|&b| b == b'e') {
            Some(e) => (&text[..e], parse_exponent(&text[e + 1..])),
            None => (text, 0),
        };
        // The point, counted in the mantissa's digits from its first; then leading zeros dropped.
        let mut point = mantissa.iter().position(|&b| b == b'.').unwrap_or(mantissa.len()) as i32;
        for &b in mantissa.iter().filter(|b| b.is_ascii_digit()) {
            if digits.len == 0 && b == b'0' {
                point -= 1;
            } else {
                digits.bytes[digits.len] = b;
                digits.len += 1;
            }
        }
        while digits.len > 0 && digits.bytes[digits.len - 1] == b'0' {
            digits.len -= 1;
        }
        (digits, point + exponent)
    }

    fn as_slice(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

/// `+300`, `-7`, `12`.
fn parse_exponent(text: &[u8]) -> i32 {
    let (negative, digits) = match text.first() {
        Some(b'-') => (true, &text[1..]),
        Some(b'+') => (false, &text[1..]),
        _ => (false, text),
    };
    let magnitude = digits.iter().fold(0i32, |n, &b| n * 10 + i32::from(b - b'0'));
    if negative { -magnitude } else { magnitude }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn display(value: f64) -> String {
        let mut buf = vec![];
        push_f64(&mut buf, value);
        String::from_utf8(buf).unwrap()
    }

    fn json(value: f64) -> String {
        let mut buf = vec![];
        push_json_f64(&mut buf, value);
        String::from_utf8(buf).unwrap()
    }

    /// A cheap, fixed stream of bit patterns (xorshift64*).
    fn bit_patterns(n: usize) -> impl Iterator<Item = u64> {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        (0..n).map(move |_| {
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            x.wrapping_mul(0x2545_F491_4F6C_DD1D)
        })
    }

    /// Values a run writes (simulation times, small decimals, whole numbers), the edges of the
    /// format (powers of ten, subnormals, the extremes) and random doubles of every magnitude.
    fn values() -> Vec<f64> {
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            0.001,
            1e-7,
            1e15,
            1e16,
            1e17,
            1e21,
            1e22,
            1e23,
            123456789012345680.0,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
            5e-324,
            f64::from_bits(0x000F_FFFF_FFFF_FFFF), // the largest subnormal
            0.30000000000000004,
            9007199254740993.0,
        ];
        values.extend((-325..=308).map(|e| 10f64.powi(e)));
        values.extend((-325..=308).map(|e| format!("1e{e}").parse::<f64>().unwrap()));
        values.extend((0..20_000).map(|k| k as f64 / 1000.0));
        values.extend((0..2_000).map(|k| k as f64 * 0.001));
        values.extend((0..2_000).map(|k| (k as f64 * 0.37).sin() * 1e-3));
        // Ties: between 2^50 and 2^51 a double's last bit is 0.25, so x.25 and x.75 lie halfway
        // between two 17-digit candidates (x.2 and x.3, x.7 and x.8).
        values.extend(bit_patterns(20_000).map(|bits| ((bits >> 14) | 1 << 50) as f64 + 0.25));
        values.extend(bit_patterns(20_000).map(|bits| ((bits >> 14) | 1 << 50) as f64 + 0.75));
        values.extend(bit_patterns(20_000).map(|bits| -(((bits >> 14) | 1 << 50) as f64 + 0.25)));
        values.extend(bit_patterns(300_000).map(f64::from_bits));
        values.extend(bit_patterns(100_000).map(|bits| f64::from_bits(bits & 0x000F_FFFF_FFFF_FFFF)));
        values.extend(bit_patterns(100_000).map(|bits| (bits >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0));
        values
    }

    #[test]
    fn floats_are_written_as_display_writes_them() {
        for value in values() {
            assert_eq!(display(value), format!("{value}"), "bits {:#x}", value.to_bits());
        }
        for value in [f64::NAN, -f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(display(value), format!("{value}"));
        }
    }

    #[test]
    fn floats_are_written_as_serde_json_writes_them() {
        for value in values().into_iter().chain([f64::NAN, f64::INFINITY, f64::NEG_INFINITY]) {
            assert_eq!(json(value), serde_json::to_string(&value).unwrap(), "bits {:#x}", value.to_bits());
        }
    }

    #[test]
    fn integers_are_written_as_display_writes_them() {
        let mut buf = vec![];
        for value in [0, 1, -1, i64::MIN, i64::MAX] {
            buf.clear();
            push_int(&mut buf, value);
            assert_eq!(buf, format!("{value}").as_bytes());
        }
        buf.clear();
        push_int(&mut buf, u64::MAX);
        assert_eq!(buf, u64::MAX.to_string().as_bytes());
    }
}
