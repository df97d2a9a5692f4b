//! Observation files: CSV `id,col,row` with a header, pixel coordinates of
//! `docs/conventions.md` (integer values are pixel centres, `row` down).

use crate::FormatError;
use std::collections::HashMap;
use std::path::Path;

/// One measured image position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelObservation {
    /// Target id.
    pub id: u64,
    /// Column, pixels.
    pub col: f64,
    /// Row, pixels.
    pub row: f64,
    /// 1-based line in the file.
    pub line: usize,
}

/// Parses observation CSV text; `origin` names the file in errors. Rejects
/// non-numeric or non-finite values and duplicated ids, naming the line.
pub fn parse_observations(text: &str, origin: &str) -> Result<Vec<PixelObservation>, FormatError> {
    let err = |line: usize, what: String| FormatError::Observations {
        origin: origin.into(),
        line,
        what,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((hl, header)) = lines.next() else {
        return Err(err(0, "empty file (expected header `id,col,row`)".into()));
    };
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    if cols != ["id", "col", "row"] {
        return Err(err(
            hl,
            format!("header is `{header}`, expected `id,col,row`"),
        ));
    }
    let mut out = Vec::new();
    let mut seen: HashMap<u64, usize> = HashMap::new();
    for (line, text) in lines {
        let f: Vec<&str> = text.split(',').map(str::trim).collect();
        if f.len() != 3 {
            return Err(err(line, format!("expected 3 columns, found {}", f.len())));
        }
        let id: u64 = f[0]
            .parse()
            .map_err(|_| err(line, format!("id `{}` is not a positive integer", f[0])))?;
        let num = |name: &str, s: &str| -> Result<f64, FormatError> {
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(_) => Err(err(line, format!("{name} `{s}` is not finite"))),
                Err(_) => Err(err(line, format!("{name} `{s}` is not a number"))),
            }
        };
        let col = num("col", f[1])?;
        let row = num("row", f[2])?;
        if let Some(first) = seen.insert(id, line) {
            return Err(err(
                line,
                format!("duplicate id {id} (first on line {first})"),
            ));
        }
        out.push(PixelObservation { id, col, row, line });
    }
    if out.is_empty() {
        return Err(err(0, "no observations".into()));
    }
    Ok(out)
}

/// Loads an observation file.
pub fn load_observations(path: &Path) -> Result<Vec<PixelObservation>, FormatError> {
    let text = crate::read_text(path, crate::FileKind::Observations)?;
    parse_observations(&text, &path.display().to_string())
}

/// Writes observations as CSV text.
pub fn observations_to_csv(obs: impl IntoIterator<Item = (u64, f64, f64)>) -> String {
    let mut s = String::from("id,col,row\n");
    for (id, col, row) in obs {
        s.push_str(&format!("{id},{col:.6},{row:.6}\n"));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_and_rejects_with_line_numbers() {
        let ok = parse_observations("id,col,row\n1,10.5,20.25\n2,3,4\n", "o.csv").unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(ok[1].line, 3);
        for (text, want) in [
            ("", "o.csv:0: empty"),
            ("id,col,row\n", "no observations"),
            (
                "id,col,row\n1,abc,2\n",
                "o.csv:2: col `abc` is not a number",
            ),
            ("id,col,row\n1,NaN,2\n", "o.csv:2: col `NaN` is not finite"),
            ("id,col,row\n1,1,2\n1,3,4\n", "o.csv:3: duplicate id 1"),
            ("id,x\n", "header"),
        ] {
            let e = parse_observations(text, "o.csv").unwrap_err().to_string();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
    }
}
