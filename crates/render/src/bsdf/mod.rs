//! BSDFs (being written).
