//! PNG and EXR helpers: bit-exact round trips, conversions and corrupt input.

use scene::image_io::*;

/// A deterministic pseudo-random sequence in [0, 1).
fn noise(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect()
}

fn err_text<T: std::fmt::Debug>(r: scene::Result<T>) -> String {
    r.expect_err("expected an error").to_string()
}

#[test]
fn png_round_trip_is_exact_on_8_bit_codes() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (13u32, 7u32);
    let codes: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 256) as u8).collect();
    let img = Image {
        width: w,
        height: h,
        channels: 3,
        data: codes.iter().map(|&c| c as f32 / 255.0).collect(),
    };
    let p = dir.path().join("rgb.png");
    write_png(&p, &img).unwrap();
    let back = read_image(&p).unwrap();
    assert_eq!(back, img);
    assert_eq!(back.get(1, 0, 0), codes[3] as f32 / 255.0);
    // Linear: code 128 reads as 128/255, no gamma curve.
    assert_eq!(back.data[0], 0.0);
    // The file on disk holds exactly the codes (decoded independently by `image`).
    let raw = image::open(&p).unwrap().to_rgb8();
    assert_eq!(raw.as_raw(), &codes);
}

#[test]
fn grey_png_reads_as_three_equal_channels_and_values_are_rounded_and_clamped() {
    let dir = tempfile::tempdir().unwrap();
    let img = Image {
        width: 4,
        height: 1,
        channels: 1,
        data: vec![-0.5, 0.5, 0.25, 2.0],
    };
    let p = dir.path().join("g.png");
    write_png(&p, &img).unwrap();
    let back = read_image(&p).unwrap();
    assert_eq!(back.channels, 3);
    // round(0.5·255) = 128, round(0.25·255) = 64, clamped ends.
    let want = [0.0, 128.0 / 255.0, 64.0 / 255.0, 1.0];
    for (i, &v) in want.iter().enumerate() {
        assert_eq!(&back.data[3 * i..3 * i + 3], &[v, v, v]);
    }
    assert_eq!(back.luminance().data[1], {
        let v: f32 = 128.0 / 255.0;
        0.2126 * v + 0.7152 * v + 0.0722 * v
    });
}

#[test]
fn rgba_png_is_composited_over_white() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.png");
    let buf = image::RgbaImage::from_raw(2, 1, vec![255, 0, 0, 255, 0, 0, 0, 0]).unwrap();
    buf.save(&p).unwrap();
    let img = read_image(&p).unwrap();
    assert_eq!(img.data, vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
}

#[test]
fn jpeg_reads_with_the_right_size() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.jpg");
    let buf = image::RgbImage::from_pixel(16, 8, image::Rgb([200, 100, 50]));
    buf.save(&p).unwrap();
    let img = read_image(&p).unwrap();
    assert_eq!((img.width, img.height, img.channels), (16, 8, 3));
    // JPEG is lossy, but a flat colour survives within a couple of codes.
    assert!((img.get(5, 3, 0) - 200.0 / 255.0).abs() < 3.0 / 255.0);
    assert!((img.get(5, 3, 2) - 50.0 / 255.0).abs() < 3.0 / 255.0);
}

#[test]
fn png_writer_rejects_bad_images_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.png");
    let mut img = Image::new(3, 2, 3);
    img.data[4] = f32::NAN;
    let e = err_text(write_png(&p, &img));
    assert!(e.contains("bad.png") && e.contains("not finite"), "{e}");
    let e = err_text(write_png(&p, &Image::new(3, 2, 4)));
    assert!(e.contains("1 or 3 channels"), "{e}");
    let mut short = Image::new(3, 2, 3);
    short.data.pop();
    assert!(err_text(write_png(&p, &short)).contains("expected 3x2x3"));
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn corrupt_images_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.png");
    write_png(&good, &Image::new(32, 32, 3)).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("empty.png", vec![]),
        ("trunc.png", bytes[..bytes.len() / 2].to_vec()),
        ("garbage.png", b"\x89PNG\r\n\x1a\nnot really".to_vec()),
        ("text.jpg", b"hello".to_vec()),
    ];
    for (name, data) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, data).unwrap();
        let e = err_text(read_image(&p));
        assert!(e.contains(name), "{e}");
    }
    assert!(err_text(read_image(dir.path().join("none.png"))).contains("none.png"));
}

#[test]
fn exr_depth_flow_rgb_round_trip_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (37u32, 19u32);
    let n = (w * h) as usize;
    let mut depth: Vec<f32> = noise(n, 1).iter().map(|v| v * 100.0).collect();
    depth[0] = 0.0;
    depth[1] = f32::MIN_POSITIVE;
    depth[2] = 1e-40; // subnormal
    depth[3] = f32::MAX;
    let p = dir.path().join("d.exr");
    write_exr_depth(&p, w, h, &depth).unwrap();
    let (rw, rh, back) = read_exr_depth(&p).unwrap();
    assert_eq!((rw, rh), (w, h));
    assert_eq!(
        back.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        depth.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );

    let u: Vec<f32> = noise(n, 2).iter().map(|v| (v - 0.5) * 300.0).collect();
    let v: Vec<f32> = noise(n, 3).iter().map(|v| (v - 0.5) * -7.0).collect();
    let p = dir.path().join("f.exr");
    write_exr_flow(&p, w, h, &u, &v).unwrap();
    let (rw, rh, ru, rv) = read_exr_flow(&p).unwrap();
    assert_eq!((rw, rh), (w, h));
    assert_eq!(ru, u);
    assert_eq!(rv, v);

    let img = Image {
        width: w,
        height: h,
        channels: 3,
        data: noise(n * 3, 4).iter().map(|v| v * 4.0 - 1.0).collect(),
    };
    let p = dir.path().join("c.exr");
    write_exr_rgb(&p, &img).unwrap();
    assert_eq!(read_exr_rgb(&p).unwrap(), img);
    // Pixel order: row-major from the top-left, channels not swapped.
    let back = read_exr_rgb(&p).unwrap();
    assert_eq!(back.get(5, 3, 1), img.data[(3 * w as usize + 5) * 3 + 1]);
}

#[test]
fn exr_readers_check_channels_and_values() {
    let dir = tempfile::tempdir().unwrap();
    let flow = dir.path().join("flow.exr");
    write_exr_flow(&flow, 4, 3, &[0.5; 12], &[1.0; 12]).unwrap();
    // Reading depth from a flow file: channel Z missing, named in the message.
    let e = err_text(read_exr_depth(&flow));
    assert!(e.contains("flow.exr") && e.contains("no channel Z"), "{e}");
    let e = err_text(read_exr_rgb(&flow));
    assert!(e.contains("no channel R"), "{e}");

    // Non-finite values are refused by the writer (nothing written) and by the reader
    // (file made with the exr crate directly).
    let nan = dir.path().join("nan.exr");
    let mut d = vec![1.0f32; 12];
    d[7] = f32::INFINITY;
    let e = err_text(write_exr_depth(&nan, 4, 3, &d));
    assert!(
        e.contains("pixel (3, 1)") && e.contains("not finite"),
        "{e}"
    );
    assert!(!nan.exists());
    {
        use exr::prelude::*;
        let ch = AnyChannel::new("Z", FlatSamples::F32(d.clone()));
        let layer = Layer::new(
            (4, 3),
            LayerAttributes::default(),
            Encoding::UNCOMPRESSED,
            AnyChannels::sort(SmallVec::from_vec(vec![ch])),
        );
        Image::from_layer(layer).write().to_file(&nan).unwrap();
    }
    let e = err_text(read_exr_depth(&nan));
    assert!(
        e.contains("nan.exr") && e.contains("pixel (3, 1)") && e.contains("not finite"),
        "{e}"
    );

    // Wrong sizes are refused by the writers, leaving nothing behind.
    let p = dir.path().join("short.exr");
    assert!(err_text(write_exr_depth(&p, 4, 3, &[0.0; 11])).contains("expected 4x3"));
    assert!(err_text(write_exr_flow(&p, 4, 3, &[0.0; 12], &[0.0; 2])).contains("channel V"));
    assert!(err_text(write_exr_depth(&p, 0, 3, &[])).contains("empty"));
    assert!(!p.exists());

    // Truncated, empty and garbage files.
    let bytes = std::fs::read(&flow).unwrap();
    for (name, data) in [
        ("trunc.exr", bytes[..bytes.len() - 20].to_vec()),
        ("half.exr", bytes[..bytes.len() / 2].to_vec()),
        ("empty.exr", vec![]),
        (
            "garbage.exr",
            vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0, 1, 2, 3],
        ),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, data).unwrap();
        let e = err_text(read_exr_flow(&p));
        assert!(e.contains(name), "{e}");
    }
}

#[test]
fn failed_write_leaves_the_old_file_and_no_temp() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("keep.png");
    let img = Image::new(2, 2, 1);
    write_png(&p, &img).unwrap();
    let before = std::fs::read(&p).unwrap();
    let mut bad = Image::new(2, 2, 1);
    bad.data[0] = f32::NAN;
    assert!(write_png(&p, &bad).is_err());
    assert_eq!(std::fs::read(&p).unwrap(), before);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("keep.png")]);
}

#[test]
fn srgb_encoding_round_trips_and_matches_known_values() {
    use scene::image_io::{linear_to_srgb, srgb_to_linear};
    // IEC 61966-2-1: mid grey 0.5 linear is code 0.7354 (188/255), code 0.5 is 0.2140
    // linear, and the linear segment below 0.0031308 is ×12.92.
    assert!((linear_to_srgb(0.5) - 0.735_357).abs() < 1e-5);
    assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
    assert!((linear_to_srgb(0.002) - 0.025_84).abs() < 1e-6);
    for i in 0..=1000 {
        let c = i as f32 / 1000.0;
        let back = linear_to_srgb(srgb_to_linear(c));
        assert!((back - c).abs() < 2e-6, "{c} → {back}");
    }
}
