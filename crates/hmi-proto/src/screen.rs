//! Screen contract (placeholder).
