//! COLMAP's model files (`cameras`, `images`, `points3D`, as `.bin` or `.txt`), the
//! frames' times, and a text exporter for the round-trip tests.
//!
//! Binary layout (little endian): `cameras.bin` = u64 count, then per camera i32 id, i32
//! model id, u64 width, u64 height, f64 × (the model's parameter count); `images.bin` =
//! u64 count, then per image i32 id, f64 qw qx qy qz tx ty tz, i32 camera id, the name
//! NUL-terminated, u64 point count, (f64 x, f64 y, i64 point id) each; `points3D.bin` = u64
//! count, then per point u64 id, f64 x y z, u8 r g b, f64 error, u64 track length, (i32
//! image id, i32 point index) each. The text files hold the same, `#` lines comments,
//! each image on two lines (its pose, then its 2D points).

use scene::error::{Error, Result};
use std::path::{Path, PathBuf};

/// One camera of `cameras.*`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    pub model: String,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}

/// One registered image of `images.*`: world → camera rotation `(w, x, y, z)` and
/// translation, OpenCV axes.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    pub q: [f64; 4],
    pub t: [f64; 3],
    pub camera_id: u32,
    pub name: String,
}

/// A sparse model: its cameras, images and 3D points (position, colour).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColmapModel {
    pub cameras: Vec<ColmapCamera>,
    pub images: Vec<ColmapImage>,
    pub points: Vec<([f64; 3], [u8; 3])>,
}

/// COLMAP's camera models by id, with their parameter counts.
const MODELS: [(&str, usize); 11] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
];

/// What `degs import colmap` needs beside the model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColmapOptions {
    /// The event file (`--events`; default `events.*` in SRC).
    pub events: Option<PathBuf>,
    /// `NAME SECONDS` per line (`--timestamps`; default SRC/timestamps.txt).
    pub timestamps: Option<PathBuf>,
    /// Seconds per unit of the number in an image's name, when there is no timestamps
    /// file (default 1: the names are seconds; 1e-6 for microseconds; 1/fps for indices).
    pub name_seconds: Option<f64>,
}

/// A model's name and parameter count by name or id; None for an unknown model.
pub(crate) fn model_params(id_or_name: &str) -> Option<(&'static str, usize)> {
    MODELS
        .iter()
        .enumerate()
        .find(|(i, (n, _))| *n == id_or_name || i.to_string() == id_or_name)
        .map(|(_, m)| *m)
}

struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    file: &'a Path,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(Error::invalid(
                self.file,
                format!("truncated at byte {} (needs {n} more)", self.at),
            ));
        };
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    fn i32(&mut self) -> Result<i32> {
        Ok(i32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    /// A count, refused when the rest of the file cannot hold `count × min_size` bytes.
    fn count(&mut self, min_size: usize, what: &str) -> Result<usize> {
        let n = self.u64()?;
        let left = (self.bytes.len() - self.at) as u64;
        if n.saturating_mul(min_size as u64) > left {
            return Err(Error::invalid(
                self.file,
                format!("truncated: {n} {what} do not fit in the {left} bytes left"),
            ));
        }
        Ok(n as usize)
    }
}

fn read(dir: &Path, name: &str) -> Result<(Vec<u8>, std::path::PathBuf)> {
    let p = dir.join(name);
    let b = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
    Ok((b, p))
}

fn id32(v: i32, file: &Path, what: &str) -> Result<u32> {
    u32::try_from(v).map_err(|_| Error::invalid(file, format!("{what} id {v}")))
}

/// The binary model in `dir`.
pub(crate) fn read_bin(dir: &Path) -> Result<ColmapModel> {
    let mut model = ColmapModel::default();
    let (b, file) = read(dir, "cameras.bin")?;
    let mut c = Cursor {
        bytes: &b,
        at: 0,
        file: &file,
    };
    for _ in 0..c.count(24, "cameras")? {
        let id = id32(c.i32()?, &file, "camera")?;
        let m = c.i32()?;
        let (name, n) = model_params(&m.to_string())
            .ok_or_else(|| Error::invalid(&file, format!("camera {id}: unknown model id {m}")))?;
        let (w, h) = (c.u64()?, c.u64()?);
        let params = (0..n).map(|_| c.f64()).collect::<Result<_>>()?;
        let size =
            |v: u64| u32::try_from(v).map_err(|_| Error::invalid(&file, format!("size {v}")));
        model.cameras.push(ColmapCamera {
            id,
            model: name.to_string(),
            width: size(w)?,
            height: size(h)?,
            params,
        });
    }
    let (b, file) = read(dir, "images.bin")?;
    let mut c = Cursor {
        bytes: &b,
        at: 0,
        file: &file,
    };
    for _ in 0..c.count(73, "images")? {
        let id = id32(c.i32()?, &file, "image")?;
        let mut v = [0.0; 7];
        for x in &mut v {
            *x = c.f64()?;
        }
        let camera_id = id32(c.i32()?, &file, "camera")?;
        let mut name = Vec::new();
        loop {
            match c.take(1)?[0] {
                0 => break,
                ch => name.push(ch),
            }
        }
        let name = String::from_utf8(name)
            .map_err(|_| Error::invalid(&file, format!("image {id}: a name that is not UTF-8")))?;
        let n = c.count(24, "2D points")?;
        c.take(24 * n)?;
        model.images.push(ColmapImage {
            id,
            q: [v[0], v[1], v[2], v[3]],
            t: [v[4], v[5], v[6]],
            camera_id,
            name,
        });
    }
    let (b, file) = read(dir, "points3D.bin")?;
    let mut c = Cursor {
        bytes: &b,
        at: 0,
        file: &file,
    };
    for _ in 0..c.count(51, "points")? {
        c.u64()?;
        let p = [c.f64()?, c.f64()?, c.f64()?];
        let rgb = c.take(3)?;
        c.f64()?;
        let n = c.count(8, "track elements")?;
        c.take(8 * n)?;
        model.points.push((p, [rgb[0], rgb[1], rgb[2]]));
    }
    Ok(model)
}

/// The non-comment, non-empty lines of `dir/name` with their line numbers.
fn lines(dir: &Path, name: &str) -> Result<(Vec<(usize, String)>, std::path::PathBuf)> {
    let p = dir.join(name);
    let text = std::fs::read_to_string(&p).map_err(|e| Error::io(&p, e))?;
    let v = (text.lines().enumerate())
        .filter(|(_, l)| !l.trim_start().starts_with('#'))
        .map(|(i, l)| (i + 1, l.to_string()))
        .collect();
    Ok((v, p))
}

fn parse<T: std::str::FromStr>(f: &[&str], k: usize, file: &Path, line: usize) -> Result<T> {
    f.get(k).and_then(|s| s.parse().ok()).ok_or_else(|| {
        Error::invalid(
            file,
            format!("line {line}: field {} missing or not a number", k + 1),
        )
    })
}

/// The text model in `dir`.
pub(crate) fn read_txt(dir: &Path) -> Result<ColmapModel> {
    let mut model = ColmapModel::default();
    let (ls, file) = lines(dir, "cameras.txt")?;
    for (n, l) in ls.iter().filter(|(_, l)| !l.trim().is_empty()) {
        let f: Vec<&str> = l.split_whitespace().collect();
        let name = f.get(1).copied().unwrap_or("");
        let (name, k) = model_params(name).ok_or_else(|| {
            Error::invalid(&file, format!("line {n}: unknown camera model {name}"))
        })?;
        if f.len() != 4 + k {
            return Err(Error::invalid(
                &file,
                format!(
                    "line {n}: {name} takes {k} parameters, the line has {}",
                    f.len().saturating_sub(4)
                ),
            ));
        }
        model.cameras.push(ColmapCamera {
            id: parse(&f, 0, &file, *n)?,
            model: name.to_string(),
            width: parse(&f, 2, &file, *n)?,
            height: parse(&f, 3, &file, *n)?,
            params: (0..k)
                .map(|i| parse(&f, 4 + i, &file, *n))
                .collect::<Result<_>>()?,
        });
    }
    let (ls, file) = lines(dir, "images.txt")?;
    // Each image takes two lines; the second (its 2D points) may be empty.
    for pair in ls.chunks(2) {
        let (n, l) = &pair[0];
        let f: Vec<&str> = l.split_whitespace().collect();
        if f.len() < 10 {
            return Err(Error::invalid(
                &file,
                format!("line {n}: an image needs 10 fields"),
            ));
        }
        let v: Vec<f64> = (1..8)
            .map(|k| parse(&f, k, &file, *n))
            .collect::<Result<_>>()?;
        model.images.push(ColmapImage {
            id: parse(&f, 0, &file, *n)?,
            q: [v[0], v[1], v[2], v[3]],
            t: [v[4], v[5], v[6]],
            camera_id: parse(&f, 8, &file, *n)?,
            name: f[9..].join(" "),
        });
    }
    let (ls, file) = lines(dir, "points3D.txt")?;
    for (n, l) in ls.iter().filter(|(_, l)| !l.trim().is_empty()) {
        let f: Vec<&str> = l.split_whitespace().collect();
        let p = [
            parse(&f, 1, &file, *n)?,
            parse(&f, 2, &file, *n)?,
            parse(&f, 3, &file, *n)?,
        ];
        let rgb = [
            parse(&f, 4, &file, *n)?,
            parse(&f, 5, &file, *n)?,
            parse(&f, 6, &file, *n)?,
        ];
        model.points.push((p, rgb));
    }
    Ok(model)
}

/// Each image's time in seconds, in the model's image order: from the timestamps file
/// (`NAME SECONDS` lines, `#` comments), else from the last number in the image's file
/// name × `name_seconds`.
pub(crate) fn timestamps(
    src: &Path,
    o: &ColmapOptions,
    images: &[ColmapImage],
) -> Result<Vec<f64>> {
    let file = o.timestamps.clone().or_else(|| {
        let p = src.join("timestamps.txt");
        p.is_file().then_some(p)
    });
    if let Some(file) = file {
        let text = std::fs::read_to_string(&file).map_err(|e| Error::io(&file, e))?;
        let mut table = std::collections::HashMap::new();
        for (i, l) in text.lines().enumerate() {
            let l = l.trim();
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let (name, secs) = l.rsplit_once(char::is_whitespace).ok_or_else(|| {
                Error::invalid(&file, format!("line {}: `NAME SECONDS` expected", i + 1))
            })?;
            let secs: f64 = secs
                .parse()
                .ok()
                .filter(|s: &f64| s.is_finite())
                .ok_or_else(|| {
                    Error::invalid(
                        &file,
                        format!("line {}: {secs} is not a time in seconds", i + 1),
                    )
                })?;
            table.insert(name.trim().to_string(), secs);
        }
        return images
            .iter()
            .map(|img| {
                table
                    .get(&img.name)
                    .copied()
                    .ok_or_else(|| Error::invalid(&file, format!("no time for image {}", img.name)))
            })
            .collect();
    }
    let scale = o.name_seconds.unwrap_or(1.0);
    images
        .iter()
        .map(|img| {
            let stem = Path::new(&img.name)
                .file_stem()
                .map(|s| s.to_string_lossy().to_string());
            last_number(stem.as_deref().unwrap_or(""))
                .map(|v| v * scale)
                .ok_or_else(|| {
                    Error::invalid(
                        src,
                        format!(
                            "image {}: no number in its name and no timestamps.txt; pass \
                         --timestamps FILE (`NAME SECONDS` lines)",
                            img.name
                        ),
                    )
                })
        })
        .collect()
}

/// The last run of digits (with a decimal point inside) in `s`.
fn last_number(s: &str) -> Option<f64> {
    let b = s.as_bytes();
    let end = b.iter().rposition(|c| c.is_ascii_digit())? + 1;
    let mut start = end;
    while start > 0 && (b[start - 1].is_ascii_digit() || b[start - 1] == b'.') {
        start -= 1;
    }
    s[start..end].trim_start_matches('.').parse().ok()
}

/// Write `model` as COLMAP text files in `dir` (no 2D points, empty tracks).
pub(crate) fn write_txt(model: &ColmapModel, dir: &Path) -> Result<()> {
    let mut cams = String::from("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    for c in &model.cameras {
        let p: Vec<String> = c.params.iter().map(|v| format!("{v:?}")).collect();
        cams += &format!(
            "{} {} {} {} {}\n",
            c.id,
            c.model,
            c.width,
            c.height,
            p.join(" ")
        );
    }
    let mut imgs = String::from("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
    for i in &model.images {
        let [w, x, y, z] = i.q;
        let [tx, ty, tz] = i.t;
        imgs += &format!(
            "{} {w:?} {x:?} {y:?} {z:?} {tx:?} {ty:?} {tz:?} {} {}\n\n",
            i.id, i.camera_id, i.name
        );
    }
    let mut pts = String::from("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[]\n");
    for (k, (p, c)) in model.points.iter().enumerate() {
        pts += &format!(
            "{} {:?} {:?} {:?} {} {} {} 0\n",
            k + 1,
            p[0],
            p[1],
            p[2],
            c[0],
            c[1],
            c[2]
        );
    }
    for (name, text) in [
        ("cameras.txt", cams),
        ("images.txt", imgs),
        ("points3D.txt", pts),
    ] {
        scene::atomic::write_bytes_atomic(&dir.join(name), text.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::last_number;

    #[test]
    fn the_last_number_of_a_name() {
        assert_eq!(last_number("frame_000123"), Some(123.0));
        assert_eq!(last_number("1616.250000"), Some(1616.25));
        assert_eq!(last_number("cam2_0042"), Some(42.0));
        assert_eq!(last_number("img"), None);
    }
}
