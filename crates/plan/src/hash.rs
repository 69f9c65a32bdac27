//! The one content hash of the project: 64-bit FNV-1a, stable on every build and platform.
//! Profiles and plans name their scene and graphs by it; `tessera bench` keys its reference
//! images by it.

/// A running 64-bit FNV-1a hash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv::new()
    }
}

impl Fnv {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// The empty hash.
    pub const fn new() -> Fnv {
        Fnv(Fnv::OFFSET)
    }

    /// Adds `b` byte by byte.
    pub fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 = (self.0 ^ u64::from(x)).wrapping_mul(Fnv::PRIME);
        }
    }

    /// Adds `b` as one part, prefixed by its length, so that parts cannot run into each other
    /// whatever bytes they hold (`"ab", "c"` and `"a", "bc"` differ).
    pub fn part(&mut self, b: &[u8]) {
        self.bytes(&(b.len() as u64).to_le_bytes());
        self.bytes(b);
    }

    /// The hash so far.
    pub fn value(self) -> u64 {
        self.0
    }

    /// The hash so far as 16 hexadecimal digits.
    pub fn hex(self) -> String {
        format!("{:016x}", self.0)
    }
}

/// The hash profiles and plans identify a scene or graph by (`SceneId::hash`, graph hashes), as
/// hex: the parts' bytes, each followed by the byte `0xff`. Texts never hold `0xff` (it is not
/// UTF-8), so text parts cannot run into each other; binary parts go through [`Fnv::part`].
pub fn text_hash(parts: &[&[u8]]) -> String {
    let mut h = Fnv::new();
    for p in parts {
        h.bytes(p);
        h.bytes(&[0xff]);
    }
    h.hex()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv_matches_the_published_test_vectors() {
        // FNV-1a 64 of "" and of "a" (the algorithm's reference values).
        assert_eq!(Fnv::new().value(), 0xcbf2_9ce4_8422_2325);
        let mut a = Fnv::new();
        a.bytes(b"a");
        assert_eq!(a.value(), 0xaf63_dc4c_8601_ec8c);
        let mut f = Fnv::new();
        f.bytes(b"foobar");
        assert_eq!(f.value(), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn parts_do_not_run_together() {
        let (mut x, mut y) = (Fnv::new(), Fnv::new());
        x.part(b"ab");
        x.part(b"c");
        y.part(b"a");
        y.part(b"bc");
        assert_ne!(x, y);
        assert_ne!(text_hash(&[b"ab", b"c"]), text_hash(&[b"a", b"bc"]));
        assert_eq!(text_hash(&[b"ab", b"c"]).len(), 16);
    }
}
