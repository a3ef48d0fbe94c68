//! Little-endian encoding of the state directory's files, and the one
//! frame every stored unit travels in: `len: u32 | crc32c: u32 | payload`.

use super::StoreError;

/// Appends little-endian fields to a buffer.
#[derive(Default)]
pub struct Put(pub Vec<u8>);

impl Put {
    pub fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    pub fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f64s(&mut self, v: &[f64]) {
        for &x in v {
            self.f64(x);
        }
    }
}

/// Reads little-endian fields from a slice; running out is
/// [`StoreError::Malformed`], never a panic.
pub struct Get<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Get<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, at: 0 }
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], StoreError> {
        let end = self.at.checked_add(N).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(StoreError::Malformed(format!(
                "{N} bytes wanted at offset {}, {} left",
                self.at,
                self.bytes.len() - self.at
            )));
        };
        let mut out = [0; N];
        out.copy_from_slice(&self.bytes[self.at..end]);
        self.at = end;
        Ok(out)
    }
    pub fn u8(&mut self) -> Result<u8, StoreError> {
        Ok(self.take::<1>()?[0])
    }
    pub fn u32(&mut self) -> Result<u32, StoreError> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    pub fn u64(&mut self) -> Result<u64, StoreError> {
        Ok(u64::from_le_bytes(self.take()?))
    }
    pub fn f64(&mut self) -> Result<f64, StoreError> {
        Ok(f64::from_le_bytes(self.take()?))
    }
    pub fn f64s<const N: usize>(&mut self) -> Result<[f64; N], StoreError> {
        let mut out = [0.0; N];
        for x in &mut out {
            *x = self.f64()?;
        }
        Ok(out)
    }
    /// Fills `out` with the next `out.len()` numbers.
    pub fn f64s_into(&mut self, out: &mut [f64]) -> Result<(), StoreError> {
        for x in out {
            *x = self.f64()?;
        }
        Ok(())
    }
    /// A count of items at least `item_bytes` long each: refused when the
    /// rest of the input could not hold them (no allocation from a lie).
    pub fn count(&mut self, item_bytes: usize) -> Result<usize, StoreError> {
        let n = self.u64()?;
        let left = (self.bytes.len() - self.at) as u64;
        if n.saturating_mul(item_bytes as u64) > left {
            return Err(StoreError::Malformed(format!(
                "{n} items announced, {left} bytes left"
            )));
        }
        Ok(n as usize)
    }
    /// Whether every byte was read.
    pub fn finish(&self) -> Result<(), StoreError> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(StoreError::Malformed(format!(
                "{} bytes left over",
                self.bytes.len() - self.at
            )))
        }
    }
}

/// Bytes of a frame's head: length and checksum.
pub const FRAME_HEAD: usize = 8;

/// Appends `payload` framed: its length, its CRC-32C, itself.
pub fn frame(out: &mut Vec<u8>, payload: &[u8]) {
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(&crc32c::crc32c(payload).to_le_bytes());
    out.extend_from_slice(payload);
}

/// What [`unframe`] found at the front of its input.
#[derive(Debug, PartialEq, Eq)]
pub enum Framed<'a> {
    /// A whole frame whose checksum matches: its payload and the bytes it
    /// took.
    Whole(&'a [u8], usize),
    /// The input ends inside the frame (a torn write).
    Torn,
    /// The checksum does not match.
    Corrupt,
}

/// Reads one frame from the front of `bytes` (not empty).
pub fn unframe(bytes: &[u8]) -> Framed<'_> {
    if bytes.len() < FRAME_HEAD {
        return Framed::Torn;
    }
    let len = u32::from_le_bytes(bytes[0..4].try_into().unwrap_or_default()) as usize;
    let crc = u32::from_le_bytes(bytes[4..8].try_into().unwrap_or_default());
    let Some(payload) = bytes.get(FRAME_HEAD..FRAME_HEAD + len) else {
        return Framed::Torn;
    };
    if crc32c::crc32c(payload) == crc {
        Framed::Whole(payload, FRAME_HEAD + len)
    } else {
        Framed::Corrupt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_reads_back_and_any_flipped_bit_is_caught() {
        let mut out = Vec::new();
        frame(&mut out, b"keyframe 7");
        assert_eq!(unframe(&out), Framed::Whole(b"keyframe 7", 18));
        for cut in 0..out.len() {
            assert_eq!(unframe(&out[..cut]), Framed::Torn, "cut at {cut}");
        }
        for bit in 0..8 * (out.len() - 4) {
            let mut bad = out.clone();
            let byte = 4 + bit / 8;
            bad[byte] ^= 1 << (bit % 8);
            assert_eq!(unframe(&bad), Framed::Corrupt, "bit {bit}");
        }
    }

    #[test]
    fn reading_past_the_end_is_an_error() {
        let mut g = Get::new(&[1, 2, 3]);
        assert!(g.u32().is_err());
        let mut p = Put::default();
        p.u64(u64::MAX);
        let mut g = Get::new(&p.0);
        assert!(g.count(1).is_err());
    }
}
