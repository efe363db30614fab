//! The screen file the model runs: the pages and components of docs/hmi.md
//! §6, typed here by hand from the document (never from the firmware's
//! tables). `tests/contract_doc.rs` parses docs/hmi.md and fails when the two
//! differ, so a component added to the document without the model fails.
//!
//! What the document does not say about the screen file (vscope, design
//! texts, `txt_maxl`) is chosen here and listed in the crate docs.

/// What kind of Nextion component a row is (docs/hmi.md "type" column).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Text component (`.txt`).
    Text,
    /// Button (`.txt` is its label; no `.val`).
    Button,
    /// Number component (`.val`, shown as an integer).
    Number,
    /// Xfloat component (`.val`, shown with `decimals` digits after the point).
    Xfloat {
        /// The decimals the document gives (its `ws1`).
        decimals: u8,
    },
}

impl Kind {
    /// Nextion's `.type` code of the component kind (Nextion Editor).
    pub fn type_code(self) -> i32 {
        match self {
            Kind::Text => 116,
            Kind::Button => 98,
            Kind::Number => 54,
            Kind::Xfloat { .. } => 59,
        }
    }

    /// Whether the kind has a numeric `.val`.
    pub fn has_val(self) -> bool {
        matches!(self, Kind::Number | Kind::Xfloat { .. })
    }

    /// Whether the kind has a text `.txt`.
    pub fn has_txt(self) -> bool {
        matches!(self, Kind::Text | Kind::Button)
    }
}

/// One component of the screen file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ComponentSpec {
    /// Page id (order of creation of the page).
    pub page: u8,
    /// Component id on its page (order of creation, from 1).
    pub id: u8,
    /// `.objname` (case-sensitive).
    pub name: &'static str,
    /// Component kind.
    pub kind: Kind,
    /// "Send Component ID" ticked in the Touch Press Event.
    pub sends_press: bool,
    /// "Send Component ID" ticked in the Touch Release Event.
    pub sends_release: bool,
    /// A number field the operator types into with the numeric keyboard
    /// (`key` attribute set). Such a field has `vscope` global: the Nextion
    /// Editor requires it for a keyboard.
    pub keyboard: bool,
    /// The text the component has in the editor (`.txt` at page load).
    pub design_txt: &'static str,
}

impl ComponentSpec {
    /// `vscope` global (keeps its value across page changes, reachable as
    /// `page.name.attr` from another page). Only the keyboard fields.
    pub fn global(&self) -> bool {
        self.keyboard
    }
}

/// One page of the screen file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageSpec {
    /// Page id.
    pub id: u8,
    /// Page name (usable in `page name` and as a `name.obj.attr` prefix).
    pub name: &'static str,
    /// The components, in id order.
    pub components: &'static [ComponentSpec],
}

const fn text(page: u8, id: u8, name: &'static str, design_txt: &'static str) -> ComponentSpec {
    ComponentSpec {
        page,
        id,
        name,
        kind: Kind::Text,
        sends_press: false,
        sends_release: false,
        keyboard: false,
        design_txt,
    }
}

/// A button that sends its id on release only.
const fn button(page: u8, id: u8, name: &'static str, label: &'static str) -> ComponentSpec {
    ComponentSpec {
        page,
        id,
        name,
        kind: Kind::Button,
        sends_press: false,
        sends_release: true,
        keyboard: false,
        design_txt: label,
    }
}

/// A button that sends its id on press and on release (Stop, motor starts).
const fn both(page: u8, id: u8, name: &'static str, label: &'static str) -> ComponentSpec {
    ComponentSpec {
        sends_press: true,
        ..button(page, id, name, label)
    }
}

const fn number(page: u8, id: u8, name: &'static str) -> ComponentSpec {
    ComponentSpec {
        page,
        id,
        name,
        kind: Kind::Number,
        sends_press: false,
        sends_release: false,
        keyboard: false,
        design_txt: "",
    }
}

const fn xfloat(page: u8, id: u8, name: &'static str, decimals: u8) -> ComponentSpec {
    ComponentSpec {
        kind: Kind::Xfloat { decimals },
        ..number(page, id, name)
    }
}

/// A field typed with the numeric keyboard.
const fn keyed(c: ComponentSpec) -> ComponentSpec {
    ComponentSpec {
        keyboard: true,
        ..c
    }
}

/// The pages of the screen file, in id order (docs/hmi.md §6). One screen
/// file holds the pages of both machine profiles (§2a).
pub static PAGES: &[PageSpec] = &[
    PageSpec {
        id: 0,
        name: "boot",
        components: &[text(0, 1, "tmsg", "Connecting..."), text(0, 2, "tver", "")],
    },
    PageSpec {
        id: 1,
        name: "mode",
        components: &[
            button(1, 1, "bfixed", "Fixed Mode"),
            button(1, 2, "badapt", "Speed-Adaptive"),
            button(1, 3, "bcalib", "Calibration"),
            button(1, 4, "bset", "Settings"),
            keyed(xfloat(1, 5, "ncoef", 2)),
            button(1, 6, "bcoef", "Apply"),
            text(1, 7, "tmsg", ""),
        ],
    },
    PageSpec {
        id: 2,
        name: "fixed",
        components: &[
            both(2, 1, "bstart", "Start"),
            button(2, 2, "bapply", "Apply"),
            keyed(xfloat(2, 3, "nspeed", 2)),
            both(2, 4, "bstop", "Stop"),
            xfloat(2, 5, "xtravel", 2),
            button(2, 6, "bback", "Back"),
            xfloat(2, 7, "xtarget", 2),
            xfloat(2, 8, "xdrum", 2),
            number(2, 9, "nplants"),
            xfloat(2, 10, "xdist", 1),
            text(2, 11, "tmsg", ""),
        ],
    },
    PageSpec {
        id: 3,
        name: "adaptive",
        components: &[
            keyed(xfloat(3, 1, "nspacing", 1)),
            button(3, 2, "bapply", "Apply"),
            button(3, 3, "bgeardn", "Gear -"),
            button(3, 4, "bgearup", "Gear +"),
            text(3, 5, "tgear", ""),
            xfloat(3, 6, "xdist", 1),
            both(3, 7, "bstop", "Stop"),
            button(3, 8, "bback", "Back"),
            xfloat(3, 9, "xtravel", 2),
            xfloat(3, 10, "xtarget", 2),
            xfloat(3, 11, "xdrum", 2),
            number(3, 12, "nplants"),
            both(3, 13, "bstart", "Start"),
            text(3, 14, "tmsg", ""),
            xfloat(3, 15, "xqf", 1),
            xfloat(3, 16, "xmult", 1),
            xfloat(3, 17, "xmiss", 1),
            xfloat(3, 18, "xcv", 1),
            xfloat(3, 19, "xwithin", 1),
            xfloat(3, 20, "xperm", 2),
            text(3, 21, "tqlabel", "Control figures, not seedling fall"),
            text(3, 22, "tslip", ""),
            text(3, 23, "tground", ""),
        ],
    },
    PageSpec {
        id: 4,
        name: "calib",
        components: &[
            button(4, 1, "bcstart", "Start run"),
            button(4, 2, "bcstop", "Stop run"),
            xfloat(4, 3, "xmeas", 2),
            keyed(xfloat(4, 4, "nactual", 2)),
            button(4, 5, "bactual", "Apply"),
            xfloat(4, 6, "xk", 3),
            keyed(xfloat(4, 7, "nk", 3)),
            button(4, 8, "bk", "Set"),
            button(4, 9, "bsave", "Save"),
            button(4, 10, "bback", "Back"),
            text(4, 11, "tgear", ""),
            text(4, 12, "tmsg", ""),
            button(4, 13, "bkind", "Coefficient"),
            text(4, 14, "tkind", ""),
        ],
    },
    PageSpec {
        id: 5,
        name: "alarm",
        components: &[text(5, 1, "talarm", ""), button(5, 2, "bok", "OK")],
    },
    PageSpec {
        id: 6,
        name: "settings",
        components: &[
            keyed(number(6, 1, "ndim")),
            button(6, 2, "bdim", "Apply"),
            button(6, 3, "bsave", "Save settings"),
            button(6, 4, "bback", "Back"),
            text(6, 5, "tver", ""),
            text(6, 6, "tmsg", ""),
            button(6, 7, "bprofile", "Machine"),
            text(6, 8, "tprofile", ""),
            button(6, 9, "benc", "Encoder direction"),
            text(6, 10, "tenc", ""),
            button(6, 11, "bdrive", "Drive"),
            button(6, 12, "bwork", "Work switch"),
            text(6, 13, "twork", ""),
            keyed(xfloat(6, 14, "nfirst", 1)),
            button(6, 15, "bfirst", "Apply"),
            button(6, 16, "bplace", "Placement"),
            text(6, 17, "tplace", ""),
            button(6, 18, "bsource", "Travel source"),
            text(6, 19, "tsource", ""),
            button(6, 20, "bwdir", "Wheel direction"),
            text(6, 21, "twdir", ""),
        ],
    },
    PageSpec {
        id: 7,
        name: "belt",
        components: &[
            both(7, 1, "bstart", "Start"),
            both(7, 2, "bstop", "Stop"),
            xfloat(7, 3, "xn1", 2),
            button(7, 4, "bset", "Settings"),
            xfloat(7, 5, "xtravel", 2),
            button(7, 6, "bpar", "Parameters"),
            xfloat(7, 7, "xn2", 2),
            number(7, 8, "nj"),
            xfloat(7, 9, "xrad", 1),
            number(7, 10, "nplants"),
            text(7, 11, "tmsg", ""),
            button(7, 12, "broll", "New roll"),
        ],
    },
    PageSpec {
        id: 8,
        name: "beltpar",
        components: &[
            keyed(xfloat(8, 1, "nspacing", 1)),
            button(8, 2, "bspacing", "Apply"),
            keyed(xfloat(8, 3, "npitch", 1)),
            button(8, 4, "bpitch", "Apply"),
            keyed(number(8, 5, "nangle")),
            button(8, 6, "bangle", "Apply"),
            keyed(number(8, 7, "nclamp")),
            button(8, 8, "bclamp", "Apply"),
            keyed(xfloat(8, 9, "nradius", 1)),
            button(8, 10, "bradius", "Apply"),
            keyed(xfloat(8, 11, "nthick", 2)),
            button(8, 12, "bthick", "Apply"),
            keyed(xfloat(8, 13, "nthresh", 3)),
            button(8, 14, "bthresh", "Apply"),
            button(8, 15, "bback", "Back"),
            text(8, 16, "tmsg", ""),
        ],
    },
    PageSpec {
        id: 9,
        name: "drive",
        components: &[
            xfloat(9, 1, "xtau", 1),
            button(9, 2, "bidsave", "Save"),
            button(9, 3, "bback", "Back"),
            xfloat(9, 4, "xnmax", 2),
            both(9, 5, "bident", "Identify"),
            xfloat(9, 6, "xdead", 1),
            number(9, 7, "nidstate"),
            both(9, 8, "bstop", "Stop"),
            text(9, 9, "tmsg", ""),
            button(9, 10, "blink", "Link"),
        ],
    },
    PageSpec {
        id: 10,
        name: "link",
        components: &[
            text(10, 1, "tlpar", ""),
            button(10, 2, "blpar", "Next"),
            number(10, 3, "nlval"),
            button(10, 4, "blval", "Apply"),
            button(10, 5, "bback", "Back"),
            text(10, 6, "tmsg", ""),
        ],
    },
];

/// The page the Nextion Editor adds for the numeric keyboard (`keybdB`)
/// when a component's `key` attribute is set: after the user's pages.
pub const KEYBOARD_PAGE: PageSpec = PageSpec {
    id: 11,
    name: "keybdB",
    components: &[],
};

/// The page with that id, if the screen file has it.
pub fn page(id: u8) -> Option<&'static PageSpec> {
    PAGES.iter().find(|p| p.id == id)
}

/// The page with that name.
pub fn page_named(name: &str) -> Option<&'static PageSpec> {
    PAGES.iter().find(|p| p.name == name)
}

impl PageSpec {
    /// The component of this page with that `.objname`.
    pub fn component(&self, name: &str) -> Option<&'static ComponentSpec> {
        self.components.iter().find(|c| c.name == name)
    }

    /// The component of this page with that `.id`.
    pub fn component_id(&self, id: u8) -> Option<&'static ComponentSpec> {
        self.components.iter().find(|c| c.id == id)
    }
}

/// One runtime attribute of a component kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Attr {
    /// Attribute name.
    pub name: &'static str,
    /// Text (`"..."`) rather than a 32-bit number.
    pub text: bool,
    /// Writable at runtime ("green" in the editor, NIS 1.17).
    pub writable: bool,
}

const fn ro(name: &'static str) -> Attr {
    Attr {
        name,
        text: false,
        writable: false,
    }
}

const fn rw(name: &'static str) -> Attr {
    Attr {
        name,
        text: false,
        writable: true,
    }
}

const TXT: Attr = Attr {
    name: "txt",
    text: true,
    writable: true,
};

const COMMON: &[Attr] = &[
    ro("type"),
    ro("id"),
    ro("vscope"),
    ro("x"),
    ro("y"),
    ro("w"),
    ro("h"),
    ro("sta"),
    ro("style"),
    rw("font"),
    rw("bco"),
    rw("pco"),
    rw("xcen"),
    rw("ycen"),
    rw("isbr"),
    rw("spax"),
    rw("spay"),
];
const TEXT_ATTRS: &[Attr] = &[TXT, ro("txt_maxl"), rw("pw"), ro("key")];
const BUTTON_ATTRS: &[Attr] = &[TXT, ro("txt_maxl"), rw("bco2"), rw("pco2")];
const NUMBER_ATTRS: &[Attr] = &[rw("val"), rw("lenth"), rw("format"), ro("key")];
const XFLOAT_ATTRS: &[Attr] = &[rw("val"), rw("vvs0"), rw("vvs1"), ro("key")];

/// The runtime attribute `name` of a component of that kind (`.objname`
/// is not readable at runtime: NIS 1.17).
pub fn attr(kind: Kind, name: &str) -> Option<Attr> {
    let own = match kind {
        Kind::Text => TEXT_ATTRS,
        Kind::Button => BUTTON_ATTRS,
        Kind::Number => NUMBER_ATTRS,
        Kind::Xfloat { .. } => XFLOAT_ATTRS,
    };
    own.iter().chain(COMMON).find(|a| a.name == name).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_one_to_n_in_order_and_names_unique_per_page() {
        for (n, p) in PAGES.iter().enumerate() {
            assert_eq!(usize::from(p.id), n);
            for (i, c) in p.components.iter().enumerate() {
                assert_eq!(usize::from(c.id), i + 1, "{}.{}", p.name, c.name);
                assert_eq!(c.page, p.id, "{}", c.name);
                assert_eq!(
                    p.components.iter().filter(|o| o.name == c.name).count(),
                    1,
                    "{}.{}",
                    p.name,
                    c.name
                );
            }
        }
    }

    #[test]
    fn only_numbers_have_val_and_only_texts_and_buttons_have_txt() {
        assert!(attr(Kind::Number, "val").is_some());
        assert!(attr(Kind::Xfloat { decimals: 1 }, "val").is_some());
        assert!(attr(Kind::Text, "val").is_none());
        assert!(attr(Kind::Button, "val").is_none());
        assert!(attr(Kind::Number, "txt").is_none());
        assert!(attr(Kind::Text, "txt").is_some_and(|a| a.text && a.writable));
        assert!(attr(Kind::Text, "objname").is_none());
        assert!(attr(Kind::Text, "txt_maxl").is_some_and(|a| !a.writable));
    }
}
