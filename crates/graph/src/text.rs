//! Reading XML files as text: UTF-8 only, with a position and a hint when a file is not.

/// Why a file's bytes are not UTF-8 text, and where (1-based line and column of the first bad
/// byte; line 1, column 1 for a UTF-16 byte-order mark).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NotUtf8 {
    /// Line of the first byte that is not UTF-8.
    pub line: u32,
    /// Column (in characters) of that byte.
    pub column: u32,
    /// What is wrong and what to do.
    pub message: String,
}

/// `bytes` as UTF-8 text (a UTF-8 byte-order mark is dropped), or where and why they are not:
/// UTF-16 files (by their byte-order mark) and legacy encodings such as Latin-1 are named, with
/// the advice to save the file as UTF-8.
pub fn utf8_text(bytes: Vec<u8>) -> Result<String, NotUtf8> {
    if bytes.starts_with(&[0xFF, 0xFE]) || bytes.starts_with(&[0xFE, 0xFF]) {
        return Err(NotUtf8 {
            line: 1,
            column: 1,
            message: "the file is UTF-16 (it starts with a UTF-16 byte-order mark); save it as UTF-8".into(),
        });
    }
    let bytes = match bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]) {
        Some(rest) => rest.to_vec(),
        None => bytes,
    };
    String::from_utf8(bytes).map_err(|e| {
        let good = e.utf8_error().valid_up_to();
        let before = String::from_utf8_lossy(&e.as_bytes()[..good]);
        let line = before.matches('\n').count() as u32 + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) as u32 + 1;
        NotUtf8 {
            line,
            column,
            message: format!(
                "byte 0x{:02X} is not UTF-8 (a Latin-1 or other legacy encoding?); save the file as UTF-8",
                e.as_bytes()[good]
            ),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utf8_passes_and_other_encodings_are_located() {
        assert_eq!(utf8_text(b"<a>\xC3\xA9</a>".to_vec()).unwrap(), "<a>é</a>");
        assert_eq!(utf8_text(b"\xEF\xBB\xBF<a/>".to_vec()).unwrap(), "<a/>");
        // Latin-1 'é' (0xE9) on line 2, after "  <b>".
        let e = utf8_text(b"<a>\n  <b>\xE9</b>\n</a>".to_vec()).unwrap_err();
        assert_eq!((e.line, e.column), (2, 6));
        assert!(e.message.contains("0xE9") && e.message.contains("UTF-8"), "{}", e.message);
        let e = utf8_text(vec![0xFF, 0xFE, b'<', 0]).unwrap_err();
        assert!(e.message.contains("UTF-16"), "{}", e.message);
    }
}

/// At most this many characters of a value from a file go into a message.
pub const EXCERPT_CHARS: usize = 60;

/// `s` as a message quotes it: whole when short, otherwise its first [`EXCERPT_CHARS`]
/// characters and its length (a file may hold a value of megabytes; a message never echoes it
/// whole).
pub fn excerpt(s: &str) -> std::borrow::Cow<'_, str> {
    match s.char_indices().nth(EXCERPT_CHARS) {
        None => std::borrow::Cow::Borrowed(s),
        Some((cut, _)) => std::borrow::Cow::Owned(format!("{}… ({} bytes)", &s[..cut], s.len())),
    }
}
