//! libFuzzer target: any bytes as a mesh file must give triangles or an
//! error naming the file, never a panic or an oversized allocation
//! (libFuzzer's -rss_limit_mb and -malloc_limit_mb catch those).
#![no_main]

use libfuzzer_sys::fuzz_target;
use realitygap_core::robot::stl::TriangleMesh;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Err(e) = TriangleMesh::parse_obj(data, Path::new("fuzz.obj")) {
        assert!(e.to_string().contains("fuzz.obj"), "{e}");
    }
});
