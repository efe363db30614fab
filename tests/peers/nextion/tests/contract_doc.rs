//! The model's screen file (`contract::PAGES`, typed by hand) against the
//! tables of docs/hmi.md §6, parsed from the markdown: a page or component
//! added to, removed from or changed in the document without the model
//! fails here.

use nextion_model::contract::{self, ComponentSpec, Kind};

const HMI_MD: &str = include_str!("../../../../docs/hmi.md");

/// One row of a page's component table, as the document states it.
#[derive(Debug, PartialEq, Eq)]
struct DocRow {
    page: u8,
    page_name: String,
    id: u8,
    name: String,
    kind: Kind,
    sends_press: bool,
    sends_release: bool,
    keyboard: bool,
    /// A design text the document gives (button label, editor default,
    /// static text), if any.
    design_txt: Option<String>,
}

fn cells(line: &str) -> Vec<String> {
    line.trim()
        .trim_start_matches('|')
        .trim_end_matches('|')
        .split('|')
        .map(|c| c.trim().to_string())
        .collect()
}

/// The first `"…"` in `s` after `after`.
fn quoted_after(s: &str, after: &str) -> Option<String> {
    let rest = &s[s.find(after)? + after.len()..];
    let start = rest.find('"')? + 1;
    let len = rest[start..].find('"')?;
    Some(rest[start..start + len].to_string())
}

fn kind(ty: &str) -> Kind {
    if ty.starts_with("Button") {
        Kind::Button
    } else if ty.starts_with("Text") {
        Kind::Text
    } else if ty.starts_with("Number") {
        Kind::Number
    } else if ty.starts_with("Xfloat") {
        let d = ty
            .split("`ws1`=")
            .nth(1)
            .and_then(|r| r.chars().next())
            .and_then(|c| c.to_digit(10))
            .unwrap_or_else(|| panic!("Xfloat without `ws1`=: {ty}"));
        Kind::Xfloat {
            decimals: u8::try_from(d).unwrap(),
        }
    } else {
        panic!("unknown component type in docs/hmi.md: {ty}")
    }
}

fn parse_doc() -> (Vec<(u8, String)>, Vec<DocRow>) {
    let mut pages = Vec::new();
    let mut rows = Vec::new();
    let mut page: Option<(u8, String)> = None;
    let mut in_table = false;
    for line in HMI_MD.lines() {
        if let Some(h) = line.strip_prefix("### Page ") {
            let (n, rest) = h.split_once(' ').expect("### Page N `name`");
            let name = rest.trim().trim_matches('`').to_string();
            let id: u8 = n.parse().expect("page number");
            pages.push((id, name.clone()));
            page = Some((id, name));
            in_table = false;
            continue;
        }
        if line.starts_with("## ") || line.starts_with("### ") {
            page = None;
            in_table = false;
            continue;
        }
        let Some((pid, pname)) = &page else { continue };
        if !line.starts_with('|') {
            in_table = false;
            continue;
        }
        let c = cells(line);
        if c.first().map(String::as_str) == Some("id")
            && c.get(1).map(String::as_str) == Some("name")
        {
            in_table = true;
            continue;
        }
        if !in_table || c.first().is_some_and(|x| x.starts_with("---")) {
            continue;
        }
        assert_eq!(c.len(), 4, "a component row has 4 cells: {line}");
        let (ty, sends) = (&c[2], &c[3]);
        let k = kind(ty);
        let (press, release) = if sends.starts_with("Press **and** Release: Send ID") {
            (true, true)
        } else if sends.starts_with("Release: Send ID") {
            (false, true)
        } else if sends.starts_with("Press: Send ID") {
            (true, false)
        } else {
            (false, false)
        };
        let design_txt = match k {
            Kind::Button => quoted_after(ty, "Button"),
            Kind::Text => quoted_after(sends, "editor default")
                .or_else(|| quoted_after(sends, "**").filter(|_| ty.contains("static"))),
            _ => None,
        };
        rows.push(DocRow {
            page: *pid,
            page_name: pname.clone(),
            id: c[0].parse().unwrap_or_else(|_| panic!("id: {line}")),
            name: c[1].trim_matches('`').to_string(),
            kind: k,
            sends_press: press,
            sends_release: release,
            keyboard: ty.contains("numeric keyboard"),
            design_txt,
        });
    }
    (pages, rows)
}

fn model_row(c: &ComponentSpec, page_name: &str, doc_design: Option<&String>) -> DocRow {
    DocRow {
        page: c.page,
        page_name: page_name.to_string(),
        id: c.id,
        name: c.name.to_string(),
        kind: c.kind,
        sends_press: c.sends_press,
        sends_release: c.sends_release,
        keyboard: c.keyboard,
        // Compared where the document gives one; else the model's must be "".
        design_txt: doc_design.map(|_| c.design_txt.to_string()),
    }
}

#[test]
fn the_model_has_every_page_and_component_of_docs_hmi_md_and_no_other() {
    let (pages, rows) = parse_doc();
    assert!(
        rows.len() > 100,
        "parsed {} rows: the parser lost the tables",
        rows.len()
    );
    let model_pages: Vec<(u8, String)> = contract::PAGES
        .iter()
        .map(|p| (p.id, p.name.to_string()))
        .collect();
    assert_eq!(model_pages, pages, "pages (id, name)");
    for row in &rows {
        let page = contract::page(row.page).expect("page");
        let c = page.component(&row.name).unwrap_or_else(|| {
            panic!(
                "docs/hmi.md page {} `{}` has `{}` (id {}); the model has not",
                row.page, row.page_name, row.name, row.id
            )
        });
        assert_eq!(&model_row(c, page.name, row.design_txt.as_ref()), row);
        if row.design_txt.is_none() {
            assert_eq!(
                c.design_txt, "",
                "{}.{}: no design text in the doc",
                page.name, c.name
            );
        }
    }
    for p in contract::PAGES {
        for c in p.components {
            assert!(
                rows.iter().any(|r| r.page == p.id && r.name == c.name),
                "the model has {}.{} (id {}); docs/hmi.md has not",
                p.name,
                c.name,
                c.id
            );
        }
    }
}

#[test]
fn the_doc_parser_reads_what_the_document_says() {
    // The parser itself, on rows whose meaning is plain in the document.
    let (_, rows) = parse_doc();
    let row = |p: u8, n: &str| rows.iter().find(|r| r.page == p && r.name == n).unwrap();
    let stop = row(3, "bstop");
    assert_eq!(
        (stop.id, stop.sends_press, stop.sends_release),
        (7, true, true)
    );
    let apply = row(3, "bapply");
    assert_eq!(
        (apply.id, apply.sends_press, apply.sends_release),
        (2, false, true)
    );
    assert_eq!(row(3, "nspacing").kind, Kind::Xfloat { decimals: 1 });
    assert!(row(3, "nspacing").keyboard);
    assert_eq!(row(0, "tmsg").design_txt.as_deref(), Some("Connecting..."));
    assert_eq!(
        row(3, "tqlabel").design_txt.as_deref(),
        Some("Control figures, not seedling fall")
    );
    assert_eq!(row(6, "bsave").design_txt.as_deref(), Some("Save settings"));
    assert!(!row(10, "nlval").keyboard);
}
