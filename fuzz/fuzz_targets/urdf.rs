//! libFuzzer target: any text as a URDF (meshes resolved beside it, in an
//! empty folder) must give a model or an error naming the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use realitygap_core::robot::{PackageResolver, RobotModel};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(xml) = std::str::from_utf8(data) else {
        return;
    };
    let source = Path::new("fuzz-urdf-dir");
    if let Err(e) = RobotModel::from_urdf_str(xml, source, &PackageResolver::new()) {
        assert!(e.to_string().contains("fuzz-urdf-dir"), "{e}");
    }
});
