//! Placeholder: the crate's contents are an issue of their own.
#![no_std]
#![cfg_attr(not(test), forbid(unsafe_code))]
