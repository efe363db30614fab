//! A minimal, deterministic SVG line/bar chart writer (fixed number
//! formatting, so reruns are byte-identical).
//!
//! Each series' path and each bar group carry `data-series="NAME"` (the
//! run report's test finds every series by it); a point with a non-finite
//! `y` breaks a line (a gap in the data); the clip path's id is made from
//! the title, so that several charts can share one HTML page.

use std::fmt::Write as _;

/// Colours for successive series.
pub const PALETTE: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#7f7f7f",
];

/// One polyline.
pub struct Series {
    pub name: String,
    pub colour: &'static str,
    pub points: Vec<(f64, f64)>,
    pub dashed: bool,
}

/// One bar group (a histogram): `(x_left, x_right, height)`.
pub struct Bars {
    pub name: String,
    pub colour: &'static str,
    pub bars: Vec<(f64, f64, f64)>,
}

/// A chart with linear axes.
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub x_ticks: Vec<f64>,
    pub y_ticks: Vec<f64>,
    pub series: Vec<Series>,
    pub bars: Vec<Bars>,
    /// Vertical reference lines `(x, label)`.
    pub v_lines: Vec<(f64, String)>,
    /// Horizontal reference lines `(y, label)`.
    pub h_lines: Vec<(f64, String)>,
}

const W: f64 = 760.0;
const H: f64 = 420.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 190.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 55.0;

/// Escapes text and attribute values (`"` too: names go into attributes).
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// An id made of the title's ASCII letters and digits.
fn slug(s: &str) -> String {
    let mut id = String::from("plot-");
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            id.push(c.to_ascii_lowercase());
        } else if !id.ends_with('-') {
            id.push('-');
        }
    }
    id
}

/// A tick label: no trailing zeros beyond what the step needs.
fn tick_label(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

impl Chart {
    fn px(&self, x: f64) -> f64 {
        let (a, b) = self.x;
        LEFT + (x - a) / (b - a) * (W - LEFT - RIGHT)
    }

    fn py(&self, y: f64) -> f64 {
        let (a, b) = self.y;
        let y = y.clamp(a, b);
        H - BOTTOM - (y - a) / (b - a) * (H - TOP - BOTTOM)
    }

    /// Renders the chart as an SVG document.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W:.0}\" height=\"{H:.0}\" \
             viewBox=\"0 0 {W:.0} {H:.0}\" font-family=\"sans-serif\" font-size=\"12\">"
        );
        let _ = writeln!(
            s,
            "<rect width=\"{W:.0}\" height=\"{H:.0}\" fill=\"white\"/>"
        );
        let _ = writeln!(
            s,
            "<text x=\"{:.1}\" y=\"22\" text-anchor=\"middle\" font-size=\"14\" font-weight=\"bold\">{}</text>",
            (LEFT + W - RIGHT) / 2.0,
            esc(&self.title)
        );
        // Grid and ticks.
        let (x0, x1) = (LEFT, W - RIGHT);
        let (y0, y1) = (H - BOTTOM, TOP);
        for &t in &self.x_ticks {
            let x = self.px(t);
            let _ = writeln!(
                s,
                "<line x1=\"{x:.1}\" y1=\"{y0:.1}\" x2=\"{x:.1}\" y2=\"{y1:.1}\" stroke=\"#e0e0e0\"/>\
                 <text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                y0 + 16.0,
                tick_label(t)
            );
        }
        for &t in &self.y_ticks {
            let y = self.py(t);
            let _ = writeln!(
                s,
                "<line x1=\"{x0:.1}\" y1=\"{y:.1}\" x2=\"{x1:.1}\" y2=\"{y:.1}\" stroke=\"#e0e0e0\"/>\
                 <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
                x0 - 6.0,
                y + 4.0,
                tick_label(t)
            );
        }
        let _ = writeln!(
            s,
            "<rect x=\"{x0:.1}\" y=\"{y1:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"black\"/>",
            x1 - x0,
            y0 - y1
        );
        let _ = writeln!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            (x0 + x1) / 2.0,
            H - 15.0,
            esc(&self.x_label)
        );
        let _ = writeln!(
            s,
            "<text transform=\"translate(18 {:.1}) rotate(-90)\" text-anchor=\"middle\">{}</text>",
            (y0 + y1) / 2.0,
            esc(&self.y_label)
        );
        // Bars.
        let mut legend: Vec<(String, &str, bool)> = Vec::new();
        for b in &self.bars {
            let _ = writeln!(s, "<g data-series=\"{}\">", esc(&b.name));
            for &(l, r, h) in &b.bars {
                let (xl, xr) = (self.px(l), self.px(r));
                let yt = self.py(h);
                let _ = writeln!(
                    s,
                    "<rect x=\"{xl:.1}\" y=\"{yt:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\" fill-opacity=\"0.55\"/>",
                    (xr - xl).max(0.5),
                    (y0 - yt).max(0.0),
                    b.colour
                );
            }
            s.push_str("</g>\n");
            legend.push((b.name.clone(), b.colour, false));
        }
        // Reference lines.
        for (v, label) in &self.v_lines {
            let x = self.px(*v);
            let _ = writeln!(
                s,
                "<line x1=\"{x:.1}\" y1=\"{y0:.1}\" x2=\"{x:.1}\" y2=\"{y1:.1}\" stroke=\"black\" stroke-dasharray=\"2 3\"/>\
                 <text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                x + 3.0,
                y1 + 12.0,
                esc(label)
            );
        }
        for (v, label) in &self.h_lines {
            let y = self.py(*v);
            let _ = writeln!(
                s,
                "<line x1=\"{x0:.1}\" y1=\"{y:.1}\" x2=\"{x1:.1}\" y2=\"{y:.1}\" stroke=\"black\" stroke-dasharray=\"2 3\"/>\
                 <text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                x0 + 4.0,
                y - 4.0,
                esc(label)
            );
        }
        // Lines.
        let clip = slug(&self.title);
        let _ = writeln!(
            s,
            "<clipPath id=\"{clip}\"><rect x=\"{x0:.1}\" y=\"{y1:.1}\" width=\"{:.1}\" height=\"{:.1}\"/></clipPath>",
            x1 - x0,
            y0 - y1
        );
        for ser in &self.series {
            let mut d = String::new();
            let mut pen_down = false;
            for &(x, y) in &ser.points {
                if !(x.is_finite() && y.is_finite()) {
                    pen_down = false;
                    continue;
                }
                let _ = write!(
                    d,
                    "{}{:.1} {:.1}",
                    match (pen_down, d.is_empty()) {
                        (true, _) => " L",
                        (false, true) => "M",
                        (false, false) => " M",
                    },
                    self.px(x),
                    self.py(y)
                );
                pen_down = true;
            }
            let _ = writeln!(
                s,
                "<path data-series=\"{}\" clip-path=\"url(#{clip})\" d=\"{d}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"{}/>",
                esc(&ser.name),
                ser.colour,
                if ser.dashed {
                    " stroke-dasharray=\"6 3\""
                } else {
                    ""
                }
            );
            legend.push((ser.name.clone(), ser.colour, ser.dashed));
        }
        // Legend.
        for (i, (name, colour, dashed)) in legend.iter().enumerate() {
            #[allow(clippy::cast_precision_loss)]
            let y = TOP + 10.0 + 18.0 * i as f64;
            let x = W - RIGHT + 12.0;
            let _ = writeln!(
                s,
                "<line x1=\"{x:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"{colour}\" stroke-width=\"3\"{}/>\
                 <text x=\"{:.1}\" y=\"{:.1}\" font-size=\"11\">{}</text>",
                x + 22.0,
                if *dashed {
                    " stroke-dasharray=\"6 3\""
                } else {
                    ""
                },
                x + 27.0,
                y + 4.0,
                esc(name)
            );
        }
        s.push_str("</svg>\n");
        s
    }
}

/// Evenly spaced ticks from `a` to `b` by `step`.
pub fn ticks(a: f64, b: f64, step: f64) -> Vec<f64> {
    let mut v = Vec::new();
    let mut i = 0u32;
    loop {
        let t = a + f64::from(i) * step;
        if t > b + step * 1e-6 {
            break;
        }
        v.push(t);
        i += 1;
    }
    v
}
