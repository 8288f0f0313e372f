//! libFuzzer target: any bytes as a Qualisys 6DOF TSV export, headerless
//! (the study's layout) or with its header, must give a run or an error
//! naming the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use realitygap_data::qualisys::{self, QualisysOptions};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let file = Path::new("fuzz.tsv");
    for opts in [QualisysOptions::collins2019(), QualisysOptions::default()] {
        if let Err(e) = qualisys::parse(data, file, &opts) {
            assert!(e.to_string().contains("fuzz.tsv"), "{e}");
        }
    }
});
