//! Binary serialisation: bincode 2 through serde, in one place (the monitor's saved state, a
//! scenario's frozen metrics, the bench's Unix-socket baseline). (bincode 3.0.0 on crates.io is
//! an empty release that does not compile.)

use anyhow::{Result, anyhow};
use serde::Serialize;
use serde::de::DeserializeOwned;

pub fn encode<T: Serialize>(value: &T, out: &mut Vec<u8>) -> Result<()> {
    out.clear();
    bincode::serde::encode_into_std_write(value, out, bincode::config::standard())
        .map_err(|e| anyhow!("bincode encode: {e}"))?;
    Ok(())
}

/// `value` as a new byte vector.
pub fn to_bytes<T: Serialize>(value: &T) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    encode(value, &mut out)?;
    Ok(out)
}

pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T> {
    bincode::serde::decode_from_slice(bytes, bincode::config::standard())
        .map(|(value, _)| value)
        .map_err(|e| anyhow!("bincode decode: {e}"))
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trip() {
        let value = (7u64, vec![1.5f64, -2.0], [3u64; 8]);
        let mut bytes = Vec::new();
        super::encode(&value, &mut bytes).unwrap();
        assert_eq!(super::decode::<(u64, Vec<f64>, [u64; 8])>(&bytes).unwrap(), value);
    }
}
