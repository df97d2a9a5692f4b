//! A minimal, allocation-free XML tokenizer for the small documents RSI
//! exchanges (`<Rob>` datagrams, `RSI_EthernetConfig.xml`): start and end
//! tags with their attributes, text, comments and declarations skipped.
//! It borrows the input and never copies; errors carry the byte offset.
//! Every byte is consumed once (a token's scan ends where the next begins),
//! so a document costs time linear in its length.

/// One token of the document.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Token<'a> {
    /// `<name attr="v" ...>` or `<name .../>` (`empty` is true for the latter).
    Start {
        /// Element name.
        name: &'a [u8],
        /// The raw attribute text between the name and `>` / `/>`.
        attrs: Attrs<'a>,
        /// `<name/>`: no content and no end tag follows.
        empty: bool,
    },
    /// `</name>`.
    End {
        /// Element name.
        name: &'a [u8],
    },
    /// Character data between tags (raw, entities not expanded).
    Text(&'a [u8]),
}

/// A tokenizer error: what went wrong and at which byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct XmlError {
    /// Byte offset in the input.
    pub at: usize,
    /// What was wrong.
    pub what: &'static str,
    /// The input ended in the middle of a construct.
    pub truncated: bool,
}

/// Iterator over the tokens of a document.
#[derive(Debug, Clone)]
pub struct Tokenizer<'a> {
    input: &'a [u8],
    pos: usize,
}

impl<'a> Tokenizer<'a> {
    /// Tokenizes `input` from its start.
    pub fn new(input: &'a [u8]) -> Self {
        Tokenizer { input, pos: 0 }
    }

    /// The byte offset of the next token.
    pub fn position(&self) -> usize {
        self.pos
    }

    fn err(&self, at: usize, what: &'static str, truncated: bool) -> XmlError {
        XmlError {
            at,
            what,
            truncated,
        }
    }

    fn find(&self, from: usize, pat: &[u8]) -> Option<usize> {
        self.input[from..]
            .windows(pat.len())
            .position(|w| w == pat)
            .map(|p| p + from)
    }

    /// The next token, `Ok(None)` at the end of the input.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Result<Option<Token<'a>>, XmlError> {
        loop {
            let input = self.input;
            if self.pos >= input.len() {
                return Ok(None);
            }
            let start = self.pos;
            if input[start] != b'<' {
                let end = input[start..]
                    .iter()
                    .position(|&b| b == b'<')
                    .map_or(input.len(), |p| p + start);
                self.pos = end;
                return Ok(Some(Token::Text(&input[start..end])));
            }
            let rest = &input[start..];
            if rest.starts_with(b"<!--") {
                let end = self.find(start + 4, b"-->").ok_or(self.err(
                    start,
                    "unterminated comment",
                    true,
                ))?;
                self.pos = end + 3;
                continue;
            }
            if rest.starts_with(b"<?") || rest.starts_with(b"<!") {
                let end = self.find(start + 2, b">").ok_or(self.err(
                    start,
                    "unterminated declaration",
                    true,
                ))?;
                self.pos = end + 1;
                continue;
            }
            if rest.len() < 2 {
                return Err(self.err(start, "input ends after '<'", true));
            }
            let (closing, name_start) = if rest[1] == b'/' {
                (true, start + 2)
            } else {
                (false, start + 1)
            };
            let name_end = input[name_start..]
                .iter()
                .position(|&b| !is_name_byte(b))
                .map_or(input.len(), |p| p + name_start);
            if name_end == name_start {
                if name_end >= input.len() {
                    return Err(self.err(start, "input ends in a tag", true));
                }
                return Err(self.err(name_start, "expected an element name", false));
            }
            let name = &input[name_start..name_end];
            // Find the tag's '>' outside quoted attribute values.
            let mut i = name_end;
            let mut quote = 0u8;
            while i < input.len() {
                let b = input[i];
                if quote != 0 {
                    if b == quote {
                        quote = 0;
                    }
                } else if b == b'"' || b == b'\'' {
                    quote = b;
                } else if b == b'>' {
                    break;
                } else if b == b'<' {
                    return Err(self.err(i, "'<' inside a tag", false));
                }
                i += 1;
            }
            if i >= input.len() {
                return Err(self.err(start, "input ends in a tag", true));
            }
            self.pos = i + 1;
            if closing {
                if input[name_end..i].iter().any(|b| !b.is_ascii_whitespace()) {
                    return Err(self.err(name_end, "junk in an end tag", false));
                }
                return Ok(Some(Token::End { name }));
            }
            let (attr_end, empty) = if input[i - 1] == b'/' && i > name_end {
                (i - 1, true)
            } else {
                (i, false)
            };
            let raw = &input[name_end..attr_end];
            if !raw.is_empty() && !raw[0].is_ascii_whitespace() {
                return Err(self.err(
                    name_end,
                    "expected whitespace after the element name",
                    false,
                ));
            }
            return Ok(Some(Token::Start {
                name,
                attrs: Attrs {
                    raw,
                    base: name_end,
                },
                empty,
            }));
        }
    }
}

fn is_name_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.' | b':')
}

/// Whether `name` is an XML name this crate writes into replies: an ASCII
/// letter or `_`, then ASCII letters, digits, `_`, `-` or `.` (no `:`, no
/// quotes, no markup; the subset of XML's Name that KUKA's tags use).
pub fn is_xml_name(name: &[u8]) -> bool {
    match name.split_first() {
        Some((first, rest)) => {
            (first.is_ascii_alphabetic() || *first == b'_')
                && rest
                    .iter()
                    .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.'))
        }
        None => false,
    }
}

/// The attributes of a start tag, parsed on demand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attrs<'a> {
    raw: &'a [u8],
    base: usize,
}

impl<'a> Attrs<'a> {
    /// Length of the raw attribute text, bytes.
    pub fn raw_len(&self) -> usize {
        self.raw.len()
    }

    /// Iterates `(name, value)` pairs; a malformed attribute gives an error.
    pub fn iter(&self) -> AttrIter<'a> {
        AttrIter {
            raw: self.raw,
            pos: 0,
            base: self.base,
        }
    }

    /// The value of attribute `name` (exact, case-sensitive match).
    pub fn get(&self, name: &[u8]) -> Result<Option<&'a [u8]>, XmlError> {
        for a in self.iter() {
            let (n, v) = a?;
            if n == name {
                return Ok(Some(v));
            }
        }
        Ok(None)
    }
}

/// Iterator over the attributes of a start tag.
#[derive(Debug, Clone)]
pub struct AttrIter<'a> {
    raw: &'a [u8],
    pos: usize,
    base: usize,
}

impl<'a> Iterator for AttrIter<'a> {
    type Item = Result<(&'a [u8], &'a [u8]), XmlError>;

    fn next(&mut self) -> Option<Self::Item> {
        let raw = self.raw;
        while self.pos < raw.len() && raw[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if self.pos >= raw.len() {
            return None;
        }
        let fail = |at: usize, what: &'static str| {
            Some(Err(XmlError {
                at,
                what,
                truncated: false,
            }))
        };
        let ns = self.pos;
        while self.pos < raw.len() && is_name_byte(raw[self.pos]) {
            self.pos += 1;
        }
        let name = &raw[ns..self.pos];
        if name.is_empty() {
            self.pos = raw.len();
            return fail(self.base + ns, "expected an attribute name");
        }
        while self.pos < raw.len() && raw[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if self.pos >= raw.len() || raw[self.pos] != b'=' {
            self.pos = raw.len();
            return fail(self.base + ns, "attribute without '='");
        }
        self.pos += 1;
        while self.pos < raw.len() && raw[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if self.pos >= raw.len() || !matches!(raw[self.pos], b'"' | b'\'') {
            self.pos = raw.len();
            return fail(self.base + ns, "attribute value not quoted");
        }
        let q = raw[self.pos];
        let vs = self.pos + 1;
        match raw[vs..].iter().position(|&b| b == q) {
            Some(p) => {
                self.pos = vs + p + 1;
                Some(Ok((name, &raw[vs..vs + p])))
            }
            None => {
                self.pos = raw.len();
                fail(self.base + ns, "unterminated attribute value")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_of_a_small_document() {
        let doc = b"<?xml version=\"1.0\"?><!-- c --><a x='1' y = \"2>3\"><b/>t</a>";
        let mut t = Tokenizer::new(doc);
        match t.next().unwrap().unwrap() {
            Token::Start { name, attrs, empty } => {
                assert_eq!(name, b"a");
                assert!(!empty);
                assert_eq!(attrs.get(b"y").unwrap(), Some(&b"2>3"[..]));
                assert_eq!(attrs.get(b"x").unwrap(), Some(&b"1"[..]));
                assert_eq!(attrs.get(b"z").unwrap(), None);
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            t.next().unwrap(),
            Some(Token::Start {
                name: b"b",
                empty: true,
                ..
            })
        ));
        assert_eq!(t.next().unwrap(), Some(Token::Text(b"t")));
        assert_eq!(t.next().unwrap(), Some(Token::End { name: b"a" }));
        assert_eq!(t.next().unwrap(), None);
    }

    #[test]
    fn truncation_is_flagged() {
        let mut t = Tokenizer::new(b"<a x=\"1");
        let e = t.next().unwrap_err();
        assert!(e.truncated, "{e:?}");
    }
}
