//! Finds the TrueType font embedded for text in PNG figures.
//!
//! Order: the `REALITYGAP_FONT` environment variable (a .ttf path), then
//! DejaVu Sans as installed by the Debian package `fonts-dejavu-core`
//! (`scripts/setup` installs it). The font is embedded with `include_bytes!`
//! so the binary needs no font at run time; no font file is kept in the
//! repository.

use std::path::Path;

const CANDIDATES: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
];

fn main() {
    println!("cargo:rerun-if-env-changed=REALITYGAP_FONT");
    let chosen = match std::env::var("REALITYGAP_FONT") {
        Ok(p) if !p.is_empty() => {
            if !Path::new(&p).is_file() {
                panic!("REALITYGAP_FONT={p} is not a file; point it to a TrueType (.ttf) font");
            }
            p
        }
        _ => match CANDIDATES.iter().find(|p| Path::new(p).is_file()) {
            Some(p) => p.to_string(),
            None => panic!(
                "no font for PNG figures: install the Debian package fonts-dejavu-core (scripts/setup does), \
                 or set REALITYGAP_FONT to a .ttf file. Looked in: {}",
                CANDIDATES.join(", ")
            ),
        },
    };
    println!("cargo:rerun-if-changed={chosen}");
    println!("cargo:rustc-env=REALITYGAP_FONT_PATH={chosen}");
}
