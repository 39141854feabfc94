//! OPNet's per-video perception pickles, written by Python's pickle with numpy exactly as OPNet's
//! scripts write them (`tests/oracle/pickles.py`: protocols 2 to 5, numpy int64 arrays, lists of
//! boxes with numpy labels, float32 and big-endian arrays, empty frames), read back by
//! `PerceptionFile::read_pickle` frame for frame; malformed ones are data errors naming the file (a
//! pickle of 2,000 nested lists too, which would overflow the decoder's stack); a detection whose
//! label is outside OPNet's class indices (`-1`) is dropped and counted, not the file.
//! Needs the Python of `scripts/test` (`KPL_PYTHON`, with numpy).
#![allow(clippy::unwrap_used, clippy::print_stderr, reason = "tests report and fail loudly")]

use std::path::Path;
use std::process::Command;

use kpl_cater::classes::opnet_class;
use kpl_cater::formats::PerceptionFile;

#[test]
fn opnets_pickles_are_read_as_python_wrote_them() {
    let python = match std::env::var("KPL_PYTHON") {
        Ok(p) => p,
        Err(_) => {
            let required = std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1");
            assert!(!required, "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set: run scripts/test");
            eprintln!("skipped: KPL_PYTHON is not set (scripts/test sets it up with numpy)");
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("kpl-cater-pickles-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/oracle/pickles.py");
    assert!(Command::new(&python).arg(&script).arg(&dir).status().unwrap().success());
    let expected: serde_json::Map<String, serde_json::Value> =
        serde_json::from_slice(&std::fs::read(dir.join("expected.json")).unwrap()).unwrap();
    assert_eq!(expected.len(), 8);
    for (name, value) in &expected {
        let (boxes, labels): (Vec<Vec<[f64; 4]>>, Vec<Vec<i64>>) =
            serde_json::from_value(value.clone()).unwrap();
        let file = PerceptionFile::read_pickle(&dir.join(name), "v", "detector").unwrap();
        assert_eq!(file.frames.len(), boxes.len(), "{name}");
        for (f, detections) in file.frames.iter().enumerate() {
            let got: Vec<(&str, [f64; 4])> = detections.iter().map(|d| (file.class_of(d), d.bbox)).collect();
            let want: Vec<(&str, [f64; 4])> =
                labels[f].iter().zip(&boxes[f]).map(|(l, b)| (opnet_class(*l).unwrap(), *b)).collect();
            assert_eq!(got, want, "{name} frame {f}");
        }
    }
    // The snitch is OPNet's class 140.
    let file = PerceptionFile::read_pickle(&dir.join("detector_p4.pkl"), "v", "detector").unwrap();
    assert!(file.has_class(0, "small_gold_spl_metal") && !file.has_class(2, "small_gold_spl_metal"));
    for (bad, says) in [
        ("bad_label.pkl", "label 500"),
        ("bad_lengths.pkl", "2 labels but 4 box coordinates"),
        ("bad_shape.pkl", "expected a dict"),
        ("bad_box.pkl", "bad box"),
        ("bad_shared.pkl", "appears twice"),
        ("not_a_pickle.pkl", "not a pickle"),
        ("nested.pkl", "nested"),
    ] {
        let e = PerceptionFile::read_pickle(&dir.join(bad), "v", "detector").unwrap_err();
        assert!(e.is_data_error(), "{bad}: {e}");
        let message = e.to_string();
        assert!(message.contains(bad) && message.contains(says), "{bad}: {message}");
    }
    // One detection labelled -1 among good ones: dropped and counted, the rest read.
    let file = PerceptionFile::read_pickle(&dir.join("minus_one.pkl"), "v", "detector").unwrap();
    assert_eq!(file.dropped.unknown_class, 1);
    let last: Vec<(&str, [f64; 4])> = file.frames[3].iter().map(|d| (file.class_of(d), d.bbox)).collect();
    assert_eq!(
        last,
        vec![
            (opnet_class(63).unwrap(), [0.0, 0.0, 319.0, 239.0]),
            (opnet_class(192).unwrap(), [30.0, 40.0, 50.0, 60.0])
        ]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
