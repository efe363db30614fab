//! Calls through function pointers that the data flow cannot resolve
//! (a waker's vtable, a trait object's method, a formatter's argument):
//! which functions each may reach.
//!
//! Any function whose address the image stores or passes around may be
//! such a call's target ([`super::graph::Graph::close`]). One rule of Rust
//! narrows that down, read from the call's place in the source (the debug
//! information's inlined functions): a formatting trait's `fmt` and the
//! `Formatter`'s own methods take a `&mut Formatter`, which only
//! `core::fmt` and formatting implementations hold, so a call elsewhere
//! cannot reach them; and a `Formatter` writing its output calls its
//! writer's `core::fmt::Write` methods, nothing else.

/// Where a call through a pointer lies, for the targets it may reach.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Class {
    /// Anywhere (no debug information to tell): any function that may be
    /// called through a pointer.
    Any,
    /// Outside formatting code: any function that may be called through
    /// a pointer, except those taking a `&mut Formatter`.
    Plain,
    /// In formatting code (`core::fmt`, a formatting implementation):
    /// any function that may be called through a pointer.
    Formatting,
    /// A `Formatter` method writing its output: the `core::fmt::Write`
    /// implementations.
    FormatterWrite,
}

impl Class {
    /// The class of a call whose enclosing functions (innermost first) are
    /// `frames`; [`Class::Any`] without them.
    pub fn of(frames: &[String]) -> Class {
        let Some(innermost) = frames.first() else {
            return Class::Any;
        };
        let writes = ["<core::fmt::Formatter>::", "<core::fmt::PostPadding>::"]
            .iter()
            .any(|p| innermost.starts_with(p))
            && !innermost.contains("::write_fmt");
        if writes {
            Class::FormatterWrite
        } else if frames.iter().any(|f| f.contains("core::fmt::")) {
            Class::Formatting
        } else {
            Class::Plain
        }
    }

    /// Whether a call of this class may reach a function with these names
    /// (several when the linker folded identical code).
    pub fn may_reach(self, names: &[String]) -> bool {
        match self {
            Class::Any | Class::Formatting => true,
            Class::Plain => !names.iter().all(|n| takes_formatter(n)),
            Class::FormatterWrite => names.iter().any(|n| {
                n.contains(" as core::fmt::Write>::") || n.starts_with("core::fmt::Write::")
            }),
        }
    }

    /// A name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Class::Any => "(function pointer)",
            Class::Plain => "(function pointer, outside formatting)",
            Class::Formatting => "(function pointer, in formatting)",
            Class::FormatterWrite => "(formatter's writer)",
        }
    }
}

/// The formatting traits whose `fmt` takes a `&mut Formatter`.
const FORMATTING_TRAITS: [&str; 9] = [
    "Debug", "Display", "LowerHex", "UpperHex", "Octal", "Binary", "LowerExp", "UpperExp",
    "Pointer",
];

/// Whether a function (by its demangled name) takes a `&mut Formatter`:
/// a formatting trait's `fmt`, or a `Formatter` method.
fn takes_formatter(name: &str) -> bool {
    let name = strip_hash(name);
    name.starts_with("<core::fmt::Formatter>::")
        || FORMATTING_TRAITS
            .iter()
            .any(|t| name.ends_with(&format!(" as core::fmt::{t}>::fmt")))
}

/// A name without its `::h0123…` hash and a `.123` suffix (LLVM's, on
/// local copies).
fn strip_hash(name: &str) -> &str {
    let name = name.split(" (.").next().unwrap_or(name);
    let name = match name.rsplit_once('.') {
        Some((head, n)) if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => head,
        _ => name,
    };
    match name.rfind("::h") {
        Some(i)
            if name[i + 3..].len() == 16
                && name[i + 3..].bytes().all(|b| b.is_ascii_hexdigit()) =>
        {
            &name[..i]
        }
        _ => name,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn classes_of_calls() {
        assert_eq!(Class::of(&[]), Class::Any);
        assert_eq!(
            Class::of(&names(&["<core::task::wake::Waker>::wake", "SysTick"])),
            Class::Plain
        );
        assert_eq!(
            Class::of(&names(&[
                "<core::fmt::Formatter>::padding",
                "<core::fmt::Formatter>::pad"
            ])),
            Class::FormatterWrite
        );
        assert_eq!(
            Class::of(&names(&[
                "<&dyn core::fmt::Debug as core::fmt::Debug>::fmt"
            ])),
            Class::Formatting
        );
        assert_eq!(
            Class::of(&names(&["core::fmt::write", "defmt::export::fmt"])),
            Class::Formatting
        );
    }

    #[test]
    fn targets_of_classes() {
        let debug = names(&["<usize as core::fmt::Debug>::fmt::h0123456789abcdef"]);
        let copy = names(&["<usize as core::fmt::Debug>::fmt.251"]);
        assert!(!Class::Plain.may_reach(&copy));
        let write = names(&["<heapless::string::String as core::fmt::Write>::write_str"]);
        let wake = names(&["rtic::export::executor::waker_wake"]);
        let folded = names(&["<u8 as core::fmt::Display>::fmt", "firmware::other"]);
        assert!(!Class::Plain.may_reach(&debug));
        assert!(Class::Plain.may_reach(&folded));
        assert!(Class::Plain.may_reach(&wake));
        assert!(Class::Formatting.may_reach(&debug));
        assert!(Class::FormatterWrite.may_reach(&write));
        assert!(!Class::FormatterWrite.may_reach(&debug));
        assert!(!Class::FormatterWrite.may_reach(&wake));
    }
}
