//! Importers, RunStore, exporters (to be written).
