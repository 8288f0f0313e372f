//! Library side of the `realitygap` command: the study definition and the
//! loading of every source it names, shared by `compare`, `report`,
//! `reproduce` and the benchmarks. The binary (`main.rs`) is a thin layer
//! of argument parsing and printing over it.

pub mod study;
