//! Studies: which scenes, which reference, which sources; the loading of
//! every source they name; and the one evaluation (study → per scene → per
//! source → reports) that `compare`, `report`, `reproduce` and the
//! benchmarks share.
//!
//! - [`study`]: the study file format ([`Study`]);
//! - [`files`]: file patterns (`*` wildcards) and their natural order;
//! - [`load`]: reading recordings and results directories ([`Roots`]);
//! - [`data_source`]: where recordings come from (`--data
//!   builtin|none|DIR`);
//! - [`measure`]: how the gap is measured ([`Measure`]: mode, alignment,
//!   registration, run selection, intervals);
//! - [`evaluate`](mod@evaluate): the evaluation itself;
//! - [`provenance`]: what a report says its runs came from;
//! - [`reproduce`]: the study `realitygap reproduce` compares;
//! - [`stitch`]: `realitygap stitch`, stitched plans (one engine per
//!   phase) chosen on training runs and scored against single engines.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod data_source;
pub mod evaluate;
pub mod files;
pub mod ik;
pub mod import;
pub mod joint_space;
pub mod load;
pub mod measure;
pub mod provenance;
pub mod replay;
pub mod reproduce;
pub mod stitch;
pub mod study;
pub mod toss_study;
pub mod tosses;

pub use data_source::DataSource;
pub use evaluate::{evaluate, evaluate_measured, evaluate_scenes, load_study};
pub use files::{glob, natural_cmp};
pub use load::{load_source, load_store, LoadedScene, Roots};
pub use measure::{parse_alignment, parse_mode, Measure, MODES};
pub use study::{expand, toml_error, SourceFormat, SourceSpec, Study, StudyScene};
