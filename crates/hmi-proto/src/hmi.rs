//! Application layer (placeholder).
