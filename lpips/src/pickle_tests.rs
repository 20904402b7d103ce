use super::*;

const P3: &[u8] = include_bytes!("../tests/data/tiny_p3.pkl");
const P4: &[u8] = include_bytes!("../tests/data/tiny_p4.pkl");

/// The fixtures: `{'Net_0': {'Conv_0': {'kernel': arange(24).reshape(2,3,1,4)*0.5-3,
/// 'bias': [1.5, -2.25]}}, 'Lin_0': {'kernel': [[0.125]]}}` as float32, written by
/// Python's pickle with protocols 3 and 4.
#[test]
fn reads_nested_float32_arrays_of_protocols_3_and_4() {
    for bytes in [P3, P4] {
        let a = read_arrays(bytes).unwrap();
        assert_eq!(
            a.keys().collect::<Vec<_>>(),
            ["Lin_0/kernel", "Net_0/Conv_0/bias", "Net_0/Conv_0/kernel"]
        );
        let k = &a["Net_0/Conv_0/kernel"];
        assert_eq!(k.shape, [2, 3, 1, 4]);
        let want: Vec<f32> = (0..24).map(|i| i as f32 * 0.5 - 3.0).collect();
        assert_eq!(k.data, want);
        assert_eq!(a["Net_0/Conv_0/bias"].data, [1.5, -2.25]);
        assert_eq!(a["Lin_0/kernel"].shape, [1, 1]);
        assert_eq!(a["Lin_0/kernel"].data, [0.125]);
    }
}

#[test]
fn every_truncation_is_an_error() {
    for bytes in [P3, P4] {
        for n in 0..bytes.len() {
            assert!(
                read_arrays(&bytes[..n]).is_err(),
                "prefix of {n} bytes accepted"
            );
        }
    }
}

#[test]
fn corrupt_bytes_never_panic() {
    // Every single-byte change: an error or (where the byte is array data or a
    // harmless length hint) a parse, never a panic or a hang.
    for bytes in [P3, P4] {
        for i in 0..bytes.len() {
            for v in [0x00, 0xff, b'.', b'(', b'h'] {
                let mut b = bytes.to_vec();
                b[i] = v;
                let _ = read_arrays(&b);
            }
        }
    }
}

#[test]
fn hostile_and_foreign_pickles_are_refused() {
    // `{'a': Evil()}` whose __reduce__ is os.system('echo pwned').
    let e = read_arrays(include_bytes!("../tests/data/hostile.pkl")).unwrap_err();
    assert!(
        e.contains("unexpected global") && e.contains("system"),
        "{e}"
    );
    // A float64 array.
    let e = read_arrays(include_bytes!("../tests/data/tiny_f64.pkl")).unwrap_err();
    assert!(e.contains("'f8'") && e.contains("float32"), "{e}");
    // Protocol 1, a huge BINUNICODE length, an empty dict.
    assert!(
        read_arrays(b"\x80\x01}.")
            .unwrap_err()
            .contains("protocol 1")
    );
    let e = read_arrays(b"\x80\x03X\xff\xff\xff\xffab").unwrap_err();
    assert!(e.contains("truncated"), "{e}");
    assert!(
        read_arrays(b"\x80\x03}.")
            .unwrap_err()
            .contains("no arrays")
    );
    // An array whose shape (2, 3, 1, 4) is changed to (2, 3, 1, 5): 96 bytes for 30.
    let pat = b"(K\x02K\x03K\x01K\x04t";
    let at = P3
        .windows(pat.len())
        .position(|w| w == pat)
        .expect("shape tuple");
    let mut b = P3.to_vec();
    b[at + 8] = 5;
    let e = read_arrays(&b).unwrap_err();
    assert!(e.contains("holds 96 bytes, not 120"), "{e}");
}
