//! Analysis (to be written).
