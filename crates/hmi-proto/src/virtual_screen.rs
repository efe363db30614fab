//! Virtual screen (placeholder).
