//! 3DGS PLY: bit-exact round trip, exact header, channel-major `f_rest`, and clear
//! errors (naming the file) for bad input.

mod python;
use gaussians::ply;
use gaussians::{Gaussian, Splats};
use python::python_with_plyfile;
use std::path::Path;

/// Deterministic awkward floats: negative zero, subnormals, large and tiny values.
fn value(i: usize, k: usize) -> f32 {
    let h = (i as u64 * 1_000_003 + k as u64 * 7919).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    match h % 7 {
        0 => -0.0,
        1 => f32::from_bits(1 + (h >> 40) as u32 % 1000), // subnormal
        2 => 3.0e38 * if h & 1 == 0 { 1.0 } else { -1.0 },
        _ => {
            f32::from_bits(0x3000_0000 + (h >> 36) as u32 % 0x1800_0000)
                * if h & 2 == 0 { 1.0 } else { -1.0 }
        }
    }
}

fn splats(n: usize, degree: u32) -> Splats {
    let nr = (degree as usize + 1).pow(2) - 1;
    (0..n)
        .map(|i| Gaussian {
            mean: std::array::from_fn(|k| value(i, k)),
            log_scale: std::array::from_fn(|k| value(i, 10 + k)),
            rotation: std::array::from_fn(|k| value(i, 20 + k)),
            opacity_logit: value(i, 30),
            sh_dc: std::array::from_fn(|k| value(i, 40 + k)),
            sh_rest: std::array::from_fn(|k| if k < 3 * nr { value(i, 50 + k) } else { 0.0 }),
            dynamic: true,
        })
        .collect()
}

fn bits(s: &Splats) -> Vec<u32> {
    let mut v = Vec::new();
    v.extend(s.means.as_flattened().iter().map(|x| x.to_bits()));
    v.extend(s.log_scales.as_flattened().iter().map(|x| x.to_bits()));
    v.extend(s.rotations.as_flattened().iter().map(|x| x.to_bits()));
    v.extend(s.opacity_logits.iter().map(|x| x.to_bits()));
    v.extend(s.sh_dc.as_flattened().iter().map(|x| x.to_bits()));
    v.extend(s.sh_rest.as_flattened().iter().map(|x| x.to_bits()));
    v
}

#[test]
fn round_trip_is_bit_exact_at_every_degree() {
    let dir = tempfile::tempdir().unwrap();
    for degree in 0..=3 {
        let s = splats(257, degree);
        let p = dir.path().join(format!("d{degree}.ply"));
        ply::write(&p, &s, degree).unwrap();
        let (r, d) = ply::read(&p).unwrap();
        assert_eq!(d, degree);
        assert_eq!(r.len(), 257);
        assert_eq!(bits(&r), bits(&s), "degree {degree}");
        // Writing what was read reproduces the same bytes.
        let p2 = dir.path().join(format!("d{degree}b.ply"));
        ply::write(&p2, &r, degree).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), std::fs::read(&p2).unwrap());
    }
    // No temp files left behind.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        names.iter().all(|n| n.to_string_lossy().ends_with(".ply")),
        "{names:?}"
    );
}

fn header_of(bytes: &[u8]) -> String {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    String::from_utf8(bytes[..end].to_vec()).unwrap()
}

#[test]
fn header_lists_exactly_the_3dgs_properties_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("h.ply");
    ply::write(&p, &splats(3, 3), 3).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let header = header_of(&bytes);
    let mut want = String::from("ply\nformat binary_little_endian 1.0\nelement vertex 3\n");
    // The 3DGS layout without its normals (always zero there, unused).
    let mut names = vec!["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
    for k in 0..45 {
        names.push(format!("f_rest_{k}"));
    }
    for n in [
        "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        names.push(n.into());
    }
    for n in &names {
        want.push_str(&format!("property float {n}\n"));
    }
    want.push_str("end_header\n");
    assert_eq!(header, want);
    assert_eq!(bytes.len(), header.len() + 3 * 59 * 4);

    // Degree 1: 9 f_rest fields.
    ply::write(&p, &splats(2, 1), 1).unwrap();
    let h1 = header_of(&std::fs::read(&p).unwrap());
    assert!(h1.contains("property float f_rest_8\nproperty float opacity\n"));
    assert!(!h1.contains("f_rest_9"));
}

/// `f_rest` is channel-major in the file: R coefficients 1..15, then G, then B.
#[test]
fn f_rest_is_channel_major_in_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.ply");
    let mut s = splats(1, 3);
    for j in 0..15 {
        for c in 0..3 {
            s.sh_rest[0][j * 3 + c] = (100 * c + j) as f32;
        }
    }
    ply::write(&p, &s, 3).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let body = &bytes[header_of(&bytes).len()..];
    let f = |k: usize| f32::from_le_bytes(body[4 * k..4 * k + 4].try_into().unwrap());
    for k in 0..45 {
        assert_eq!(f(6 + k), (100 * (k / 15) + k % 15) as f32, "f_rest_{k}");
    }
    // x is the first float, f_dc_0 the fourth (no normals between).
    assert_eq!(f(0).to_bits(), s.means[0][0].to_bits());
    assert_eq!(f(3).to_bits(), s.sh_dc[0][0].to_bits());
}

/// A file in the original 3DGS layout, with its normals `nx ny nz` after the position
/// (what the Inria code and most tools write), reads as the same Gaussians.
#[test]
fn the_layout_with_normals_is_read() {
    let dir = tempfile::tempdir().unwrap();
    for degree in [0u32, 3] {
        let s = splats(5, degree);
        let p = dir.path().join(format!("n{degree}.ply"));
        ply::write(&p, &s, degree).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let header = header_of(&bytes);
        let floats = ply::layout(degree, false).len();
        // Rewrite with three zero floats after x y z in every vertex.
        let with = header.replace(
            "property float z\n",
            "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n",
        );
        let mut out = with.into_bytes();
        for v in bytes[header.len()..].chunks(4 * floats) {
            out.extend(&v[..12]);
            out.extend([0u8; 12]);
            out.extend(&v[12..]);
        }
        let q = dir.path().join(format!("n{degree}-normals.ply"));
        std::fs::write(&q, &out).unwrap();
        let (r, d) = ply::read(&q).unwrap();
        assert_eq!(d, degree);
        assert_eq!(bits(&r), bits(&s), "degree {degree}");
    }
}

fn expect_err(path: &Path, bytes: &[u8], what: &str) {
    std::fs::write(path, bytes).unwrap();
    let e = ply::read(path).expect_err(what).to_string();
    assert!(
        e.contains(&path.display().to_string()),
        "{what}: error does not name the file: {e}"
    );
    eprintln!("{what}: {e}");
}

#[test]
fn bad_input_gives_errors_that_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ply");
    ply::write(&good, &splats(5, 2), 2).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let hlen = header_of(&bytes).len();
    let p = dir.path().join("bad.ply");

    expect_err(&p, b"", "empty");
    expect_err(&p, b"not a ply at all", "not PLY");
    for cut in [3, hlen - 5, hlen, hlen + 1, bytes.len() - 1] {
        expect_err(&p, &bytes[..cut], &format!("truncated at {cut}"));
    }
    // NaN in the opacity of Gaussian 3 (degree 2: 38 floats, opacity the 31st).
    let mut nan = bytes.clone();
    let (per, op) = (ply::property_names(2).len(), 6 + 24);
    assert_eq!((per, ply::property_names(2)[op].as_str()), (38, "opacity"));
    let off = hlen + 3 * 4 * per + 4 * op;
    nan[off..off + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    expect_err(&p, &nan, "NaN");
    let e = ply::read(&p).unwrap_err().to_string();
    assert!(e.contains("Gaussian 3") && e.contains("opacity"), "{e}");
    // Wrong property name / order / type.
    let h = header_of(&bytes);
    for (from, to) in [
        ("property float opacity", "property float opacitx"),
        (
            "property float scale_0\nproperty float scale_1",
            "property float scale_1\nproperty float scale_0",
        ),
        ("property float rot_3", "property double rot_3"),
    ] {
        let mut b = h.replacen(from, to, 1).into_bytes();
        b.extend_from_slice(&bytes[hlen..]);
        expect_err(&p, &b, &format!("properties {to}"));
    }
    // Zero vertices, and a hostile count.
    let mut b = h
        .replacen("element vertex 5", "element vertex 0", 1)
        .into_bytes();
    expect_err(&p, &b, "zero");
    assert!(ply::read(&p).unwrap_err().to_string().contains("zero"));
    b = h
        .replacen("element vertex 5", "element vertex 99999999999999", 1)
        .into_bytes();
    b.extend_from_slice(&bytes[hlen..]);
    expect_err(&p, &b, "huge count");
    // Missing file.
    let missing = dir.path().join("missing.ply");
    assert!(
        ply::read(&missing)
            .unwrap_err()
            .to_string()
            .contains("missing.ply")
    );
}

#[test]
fn write_refuses_non_finite_and_leaves_the_old_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.ply");
    ply::write(&p, &splats(4, 0), 0).unwrap();
    let before = std::fs::read(&p).unwrap();
    let mut s = splats(4, 0);
    s.means[2][1] = f32::INFINITY;
    let e = ply::write(&p, &s, 0).unwrap_err().to_string();
    assert!(e.contains("m.ply") && e.contains("Gaussian 2"), "{e}");
    assert_eq!(std::fs::read(&p).unwrap(), before);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

/// An independent reader (Python `plyfile`) opens our file with the exact 3DGS property
/// list and values. The interpreter comes from [`python_with_plyfile`]; when none can be
/// had the test fails, unless `DEGS_SKIP_PLYFILE=1` opts out (then it says it skipped).
#[test]
fn plyfile_reads_our_output() {
    let python = match python_with_plyfile() {
        Ok(py) => py,
        Err(why) => {
            if std::env::var("DEGS_SKIP_PLYFILE").is_ok_and(|v| v == "1") {
                eprintln!("SKIPPED: no Python with plyfile ({why}) and DEGS_SKIP_PLYFILE=1");
                return;
            }
            panic!(
                "no Python with plyfile, the independent PLY reader this test needs: {why}. \
                 Install it (`pip install plyfile`), point DEGS_PYTHON at an interpreter that \
                 has it, or opt out with DEGS_SKIP_PLYFILE=1"
            );
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("py.ply");
    let mut s = splats(4, 3);
    for i in 0..4 {
        s.means[i] = [i as f32, 0.5, -0.25];
        s.opacity_logits[i] = -(i as f32);
        for j in 0..15 {
            for c in 0..3 {
                s.sh_rest[i][j * 3 + c] = (100 * c + j) as f32;
            }
        }
    }
    ply::write(&p, &s, 3).unwrap();
    let script = r#"
import sys
from plyfile import PlyData
d = PlyData.read(sys.argv[1])
v = d['vertex']
names = [p.name for p in v.properties]
want = ['x','y','z','f_dc_0','f_dc_1','f_dc_2'] + ['f_rest_%d' % k for k in range(45)] + ['opacity','scale_0','scale_1','scale_2','rot_0','rot_1','rot_2','rot_3']
assert names == want, names
assert all(str(p.val_dtype).endswith('f4') for p in v.properties), [p.val_dtype for p in v.properties]
assert len(v.data) == 4
assert list(v['x']) == [0.0, 1.0, 2.0, 3.0]
assert list(v['opacity']) == [0.0, -1.0, -2.0, -3.0]
assert v['f_rest_16'][2] == 101.0 and v['f_rest_44'][0] == 214.0
print('ok')
"#;
    let out = std::process::Command::new(&python)
        .args(["-c", script, p.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "plyfile rejected our PLY: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Three Gaussians in front of a camera at the origin (looking down −Z), degree 0.
fn front_row() -> Splats {
    [-0.4f32, 0.0, 0.4]
        .iter()
        .enumerate()
        .map(|(i, &x)| Gaussian {
            mean: [x, 0.0, -3.0],
            log_scale: [-2.0; 3],
            rotation: [1.0, 0.0, 0.0, 0.0],
            opacity_logit: 2.0,
            sh_dc: [i as f32 * 0.5, 1.0 - i as f32 * 0.5, 0.3],
            sh_rest: [0.0; 45],
            dynamic: true,
        })
        .collect()
}

#[test]
fn minus_inf_opacities_are_dropped_and_counted_nan_and_plus_inf_are_not() {
    use gaussians::raster::TileRasterizer;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("other_tool.ply");
    ply::write(&p, &front_row(), 0).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let hlen = header_of(&bytes).len();
    // Degree 0: 14 floats per Gaussian, opacity the 7th. Gaussian 1 → −inf.
    assert_eq!(ply::property_names(0)[6], "opacity");
    let opacity_at = |i: usize| hlen + i * 14 * 4 + 6 * 4;
    let mut b = bytes.clone();
    b[opacity_at(1)..opacity_at(1) + 4].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
    std::fs::write(&p, &b).unwrap();
    let c = ply::read_counted(&p).unwrap();
    assert_eq!((c.splats.len(), c.dropped_transparent, c.degree), (2, 1, 0));
    // What is left is Gaussians 0 and 2, bit for bit.
    let row = front_row();
    let mut kept = Splats::with_capacity(2);
    for i in [0, 2] {
        kept.push(row.get(i));
    }
    assert_eq!(bits(&c.splats), bits(&kept));
    // It renders, and exactly as the cloud without the transparent Gaussian.
    let cam = scene::Camera {
        intrinsics: scene::Intrinsics::from_fov_x(32, 24, 1.0),
        cam_to_world: scene::Pose::default(),
    };
    let r = TileRasterizer::new();
    let (a, _) = r.render_full(&c.splats, &cam, 0, [0.0; 3]);
    let (e, _) = r.render_full(&kept, &cam, 0, [0.0; 3]);
    assert_eq!(a.rgb, e.rgb);
    assert!(a.rgb.iter().all(|v| v.is_finite()));
    let centre = 12 * 32 + 16; // between the two kept Gaussians: covered by neither fully
    let left = 12 * 32 + (15.5 - 0.4 / 3.0 * cam.intrinsics.fx).round() as usize;
    assert!(a.alpha[left] > 0.5, "alpha {}", a.alpha[left]);
    assert!(a.alpha[centre] < a.alpha[left]);
    // NaN and +inf opacities stay errors; a cloud of only −inf has nothing to load.
    for (v, want) in [(f32::NAN, "not finite"), (f32::INFINITY, "not finite")] {
        let mut b = bytes.clone();
        b[opacity_at(2)..opacity_at(2) + 4].copy_from_slice(&v.to_le_bytes());
        std::fs::write(&p, &b).unwrap();
        let e = ply::read(&p).unwrap_err().to_string();
        assert!(
            e.contains("other_tool.ply") && e.contains("Gaussian 2") && e.contains(want),
            "{e}"
        );
    }
    let mut b = bytes.clone();
    for i in 0..3 {
        b[opacity_at(i)..opacity_at(i) + 4].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
    }
    std::fs::write(&p, &b).unwrap();
    let e = ply::read(&p).unwrap_err().to_string();
    assert!(e.contains("all 3 Gaussians have opacity −inf"), "{e}");
}
