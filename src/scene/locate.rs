//! Finds where in a JSON text a value lives, given its path (`objects[3].material`),
//! so errors found after parsing (an unknown material name, a non-finite
//! number) can still name the line and column. A small recursive scanner
//! over the same text serde_json already accepted.

/// One step of a JSON path.
#[derive(Clone, Debug, PartialEq)]
pub enum Seg {
    Key(String),
    Index(usize),
}

/// Renders a path as `a.b[3].c`.
pub fn path_string(path: &[Seg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// 1-based (line, column) of the value at `path`, or of the deepest prefix
/// of it that exists.
pub fn locate(text: &str, path: &[Seg]) -> (usize, usize) {
    let bytes = text.as_bytes();
    let mut pos = skip_ws(bytes, 0);
    for seg in path {
        match find_child(bytes, pos, seg) {
            Some(p) => pos = p,
            None => break,
        }
    }
    line_col(text, pos)
}

fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let before = &text[..pos.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rfind('\n').map_or(before.len(), |i| before.len() - i - 1) + 1;
    (line, col)
}

/// The first index at or after `i` that is not JSON whitespace.
pub fn skip_ws(b: &[u8], mut i: usize) -> usize {
    while i < b.len() && b[i].is_ascii_whitespace() {
        i += 1;
    }
    i
}

/// Position of the child value `seg` of the container starting at `pos`.
fn find_child(b: &[u8], pos: usize, seg: &Seg) -> Option<usize> {
    match (b.get(pos)?, seg) {
        (b'{', Seg::Key(key)) => {
            let mut i = skip_ws(b, pos + 1);
            while i < b.len() && b[i] == b'"' {
                let end = skip_string(b, i)?;
                let k = std::str::from_utf8(&b[i + 1..end - 1]).ok()?;
                i = skip_ws(b, end);
                i = skip_ws(b, i + 1); // ':'
                if k == key {
                    return Some(i);
                }
                i = skip_ws(b, skip_value(b, i)?);
                if b.get(i) == Some(&b',') {
                    i = skip_ws(b, i + 1);
                }
            }
            None
        }
        (b'[', Seg::Index(n)) => {
            let mut i = skip_ws(b, pos + 1);
            for _ in 0..*n {
                i = skip_ws(b, skip_value(b, i)?);
                if b.get(i) != Some(&b',') {
                    return None;
                }
                i = skip_ws(b, i + 1);
            }
            (b.get(i) != Some(&b']')).then_some(i)
        }
        _ => None,
    }
}

/// End (exclusive) of the JSON string whose opening quote is at `i`.
pub fn skip_string(b: &[u8], mut i: usize) -> Option<usize> {
    i += 1;
    while i < b.len() {
        match b[i] {
            b'\\' => i += 2,
            b'"' => return Some(i + 1),
            _ => i += 1,
        }
    }
    None
}

/// End (exclusive) of the JSON value starting at `i` (a scalar ends at a
/// separator or whitespace; may be empty); None if it runs off the text.
pub fn skip_value(b: &[u8], i: usize) -> Option<usize> {
    match b.get(i)? {
        b'"' => skip_string(b, i),
        b'{' | b'[' => {
            let mut depth = 0usize;
            let mut j = i;
            while j < b.len() {
                match b[j] {
                    b'"' => {
                        j = skip_string(b, j)?;
                        continue;
                    }
                    b'{' | b'[' => depth += 1,
                    b'}' | b']' => {
                        depth -= 1;
                        if depth == 0 {
                            return Some(j + 1);
                        }
                    }
                    _ => {}
                }
                j += 1;
            }
            None
        }
        _ => {
            let mut j = i;
            while j < b.len() && !matches!(b[j], b',' | b'}' | b']') && !b[j].is_ascii_whitespace() {
                j += 1;
            }
            Some(j)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_nested_values() {
        let text =
            "{\n  \"a\": 1,\n  \"objects\": [\n    {\"m\": \"x\"},\n    {\"s\": [1, 2], \"m\": \"glas\"}\n  ]\n}";
        let path = [Seg::Key("objects".into()), Seg::Index(1), Seg::Key("m".into())];
        assert_eq!(locate(text, &path), (5, 24));
        assert_eq!(path_string(&path), "objects[1].m");
        // A missing tail stops at the deepest prefix.
        let path = [Seg::Key("objects".into()), Seg::Index(7)];
        assert_eq!(locate(text, &path), (3, 14));
    }
}
