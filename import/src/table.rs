//! Small white-space separated text tables (ECD's `images.txt`, `groundtruth.txt`,
//! `calib.txt`; HS-ERGB's `timestamps.txt`): `#` comments and blank lines skipped,
//! errors naming the file and the line.

use scene::error::{Error, IoContext, Result};
use std::path::Path;

/// One data line: its 1-based line number and its fields.
pub struct Row<'a> {
    pub line: usize,
    pub fields: Vec<&'a str>,
}

/// Read `path` as UTF-8 text (an error names the file).
pub fn read_text(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).at(path)?;
    String::from_utf8(bytes).map_err(|_| Error::invalid(path, "not UTF-8 text"))
}

/// The data lines of `text`, each with at least `min` and at most `max` fields.
pub fn rows<'a>(path: &Path, text: &'a str, min: usize, max: usize) -> Result<Vec<Row<'a>>> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() || fields[0].starts_with('#') {
            continue;
        }
        if fields.len() < min || fields.len() > max {
            let want = if min == max {
                format!("{min}")
            } else {
                format!("{min} to {max}")
            };
            return Err(Error::invalid(
                path,
                format!("line {}: {} fields, expected {want}", i + 1, fields.len()),
            ));
        }
        out.push(Row {
            line: i + 1,
            fields,
        });
    }
    Ok(out)
}

/// Field `k` of `row` as a finite number.
pub fn number(path: &Path, row: &Row, k: usize, name: &str) -> Result<f64> {
    let s = row.fields[k];
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(Error::invalid(
            path,
            format!("line {}: {name} {s:?} is not a finite number", row.line),
        )),
    }
}

/// Check that `times` strictly increase; the error names the row's line.
pub(crate) fn check_increasing(path: &Path, rows: &[Row], times: &[f64]) -> Result<()> {
    if let Some(i) = times.windows(2).position(|w| w[1] <= w[0]) {
        return Err(Error::invalid(
            path,
            format!(
                "line {}: timestamp {} is not after the previous one ({})",
                rows[i + 1].line,
                times[i + 1],
                times[i]
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_skip_comments_and_check_counts() {
        let p = Path::new("t.txt");
        let text = "# header\n\n1 2 3\n  4 5 6  \n";
        let r = rows(p, text, 3, 3).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!((r[1].line, number(p, &r[1], 2, "z").unwrap()), (4, 6.0));
        let e = rows(p, "1 2\n", 3, 3).err().unwrap().to_string();
        assert!(
            e.contains("t.txt") && e.contains("line 1: 2 fields, expected 3"),
            "{e}"
        );
        let r = rows(p, "1 nan x\n", 3, 3).unwrap();
        let e = number(p, &r[0], 1, "y").unwrap_err().to_string();
        assert!(e.contains("y \"nan\" is not a finite number"), "{e}");
        let r = rows(p, "1\n1\n", 1, 1).unwrap();
        let e = check_increasing(p, &r, &[1.0, 1.0])
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2"), "{e}");
    }
}
