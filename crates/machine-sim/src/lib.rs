//! Placeholder: the machine simulator is an issue of its own.
#![no_std]
