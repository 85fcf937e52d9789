//! Checks of the HTML reports shared by the tests: the audit's sections, and every inline
//! SVG parsed as XML.
#![allow(dead_code)]

use std::collections::BTreeMap;

use quick_xml::events::Event;
use quick_xml::Reader;

/// The ids of the audit report's sections, in order.
pub const SECTIONS: [&str; 11] = [
    "trust",
    "actions",
    "map",
    "least-certain",
    "soil-speeds",
    "notes",
    "summary",
    "misfit",
    "speed-diameter",
    "worst-fits",
    "failed",
];

/// The HTML of the section with id `id` (panics when missing).
pub fn section<'a>(html: &'a str, id: &str) -> &'a str {
    let open = format!("<section id=\"{id}\">");
    let start = html
        .find(&open)
        .unwrap_or_else(|| panic!("section {id} missing"));
    let len = html[start..].find("</section>").expect("unclosed section");
    &html[start..start + len]
}

/// The text of each cell of each table row after the header (tags stripped, entities kept).
pub fn table_rows(fragment: &str) -> Vec<Vec<String>> {
    fragment
        .split("<tr>")
        .skip(1)
        .filter(|r| r.contains("<td"))
        .map(|r| {
            r.split("<td")
                .skip(1)
                .map(|c| {
                    let c = &c[c.find('>').map_or(0, |i| i + 1)..];
                    let c = &c[..c.find("</td>").unwrap_or(c.len())];
                    strip_tags(c)
                })
                .collect()
        })
        .collect()
}

fn strip_tags(s: &str) -> String {
    let mut out = String::new();
    let mut in_tag = false;
    for ch in s.chars() {
        match ch {
            '<' => in_tag = true,
            '>' => in_tag = false,
            c if !in_tag => out.push(c),
            _ => {}
        }
    }
    out
}

/// Every `<svg ...>...</svg>` of the page (SVG elements do not nest in our output except
/// inside one another, which the scan handles by depth).
pub fn svgs(html: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut rest = html;
    while let Some(start) = rest.find("<svg") {
        let tail = &rest[start..];
        let mut depth = 0usize;
        let mut i = 0;
        let end = loop {
            let next_open = tail[i..].find("<svg").map(|k| k + i);
            let next_close = tail[i..]
                .find("</svg>")
                .map(|k| k + i)
                .expect("unclosed <svg>");
            match next_open {
                Some(o) if o < next_close => {
                    depth += 1;
                    i = o + 4;
                }
                _ => {
                    depth -= 1;
                    i = next_close + 6;
                    if depth == 0 {
                        break i;
                    }
                }
            }
        };
        out.push(&tail[..end]);
        rest = &tail[end..];
    }
    out
}

/// Parse as XML: well-formed (matching end tags, quoted attributes, escaped text), else panic
/// with the position. Returns the element names seen.
pub fn parse_xml(doc: &str) -> BTreeMap<String, usize> {
    let mut r = Reader::from_str(doc);
    let mut names = BTreeMap::new();
    let mut depth = 0i64;
    loop {
        match r.read_event() {
            Ok(Event::Start(e)) => {
                depth += 1;
                for a in e.attributes() {
                    let a = a.unwrap_or_else(|err| panic!("bad attribute: {err}"));
                    a.normalized_value(quick_xml::XmlVersion::Implicit1_0)
                        .unwrap_or_else(|err| panic!("bad attribute value: {err}"));
                }
                *names
                    .entry(String::from_utf8_lossy(e.name().as_ref()).into_owned())
                    .or_default() += 1;
            }
            Ok(Event::Empty(e)) => {
                for a in e.attributes() {
                    a.unwrap_or_else(|err| panic!("bad attribute: {err}"));
                }
                *names
                    .entry(String::from_utf8_lossy(e.name().as_ref()).into_owned())
                    .or_default() += 1;
            }
            Ok(Event::End(_)) => depth -= 1,
            Ok(Event::Text(t)) => {
                t.decode().unwrap_or_else(|err| panic!("bad text: {err}"));
            }
            Ok(Event::Eof) => break,
            Ok(_) => {}
            Err(e) => panic!("SVG is not well-formed at {}: {e}", r.buffer_position()),
        }
    }
    assert_eq!(depth, 0, "unbalanced elements");
    names
}
