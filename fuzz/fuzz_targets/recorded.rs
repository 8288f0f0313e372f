//! libFuzzer target: any bytes as a recorded simulator file, in both
//! quaternion orders, must give a run or an error naming the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use realitygap_data::recorded::{self, QuatOrder, RecordedOptions};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let file = Path::new("fuzz.csv");
    for order in [QuatOrder::Wxyz, QuatOrder::Xyzw] {
        if let Err(e) = recorded::parse(data, file, &RecordedOptions::new(order)) {
            assert!(e.to_string().contains("fuzz.csv"), "{e}");
        }
    }
});
