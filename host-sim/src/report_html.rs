//! The self-contained HTML report (`--report out.html`) of `sweep`, `track` and `gap`: one file
//! with the command line, the controller and plant, the figures the command prints as a table
//! and its pictures as inline SVG. Nothing in it refers outside the file (no stylesheet, script,
//! font or image to fetch), so it can be mailed or archived beside the log it describes.
//!
//! The numbers are read from the same JSON value `--json` writes, by JSON pointer, so the table
//! and the JSON cannot disagree; each value cell names its pointer (`data-json`).

use serde_json::Value;
use std::fmt::Write as _;
use std::path::Path;

/// Text escaped for HTML content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            // Control characters (but line breaks and tabs) are not allowed in HTML text.
            c if c.is_control() && c != '\n' && c != '\t' => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

/// The program's own command line, quoted so it can be pasted into a POSIX shell again; the
/// program by its name, not the path it was started from (a build directory on someone's
/// machine says nothing in an archived report).
pub fn command_line() -> String {
    let mut args = std::env::args();
    let program = args
        .next()
        .map(|p| {
            Path::new(&p)
                .file_name()
                .map_or(p.clone(), |n| n.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "host-sim".into());
    std::iter::once(program)
        .chain(args)
        .map(|a| shell_quote(&a))
        .collect::<Vec<_>>()
        .join(" ")
}

/// What made a report: when (UTC), on which host, from which commit of the source tree, so an
/// archived page says where its figures came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Provenance {
    /// `YYYY-MM-DD HH:MM:SS UTC`.
    pub date: String,
    pub host: String,
    /// The source tree's commit when the report was written, `+ uncommitted changes` if it had
    /// any; `unknown` outside a git checkout (an unpacked archive, an installed binary).
    pub commit: String,
    /// host-sim's version.
    pub version: &'static str,
}

impl Provenance {
    /// This process, now.
    pub fn now() -> Provenance {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        Provenance {
            date: utc_date(secs),
            host: host_name(),
            commit: source_commit(Path::new(env!("CARGO_MANIFEST_DIR"))),
            version: env!("CARGO_PKG_VERSION"),
        }
    }

    /// The line the page shows.
    pub fn line(&self) -> String {
        format!(
            "made {} on {}, host-sim {} at commit {}",
            self.date, self.host, self.version, self.commit
        )
    }
}

/// `secs` since the Unix epoch as a UTC date and time (the civil calendar from the day count,
/// Howard Hinnant's days-to-civil).
pub fn utc_date(secs: u64) -> String {
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .or_else(|| std::env::var("COMPUTERNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown host".into())
}

/// The commit of the git checkout at `dir`, if it is one and git is there.
fn source_commit(dir: &Path) -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .arg("-C")
            .arg(dir)
            .args(args)
            .stdin(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(commit) if !commit.is_empty() => {
            let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
            if dirty {
                format!("{commit} + uncommitted changes")
            } else {
                commit
            }
        }
        _ => "unknown (not a git checkout)".into(),
    }
}

fn shell_quote(arg: &str) -> String {
    let plain = !arg.is_empty()
        && arg
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
    if plain {
        arg.to_string()
    } else {
        format!("'{}'", arg.replace('\'', r"'\''"))
    }
}

/// One line of the figures table.
#[derive(Debug)]
struct Row {
    name: String,
    value: String,
    unit: String,
    /// The JSON pointer the value was read from.
    pointer: String,
    /// A number, aligned right; text reads better aligned left.
    numeric: bool,
}

/// A further table (e.g. the diagnosis's ranking), cells already formatted.
#[derive(Debug)]
struct Table {
    caption: String,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

#[derive(Debug)]
struct Figure {
    caption: String,
    svg: String,
}

/// A number of the figures table: its name, where it is in the JSON, how it is shown.
#[derive(Debug, Clone, Copy)]
pub struct Num<'a> {
    name: &'a str,
    pointer: &'a str,
    unit: &'a str,
    scale: f64,
    decimals: usize,
    absent: &'a str,
}

/// The number at JSON pointer `pointer`, in `unit`, with two decimals ("-" for a null).
pub fn num<'a>(name: &'a str, pointer: &'a str, unit: &'a str) -> Num<'a> {
    Num {
        name,
        pointer,
        unit,
        scale: 1.0,
        decimals: 2,
        absent: "-",
    }
}

impl<'a> Num<'a> {
    pub fn decimals(self, decimals: usize) -> Self {
        Self { decimals, ..self }
    }

    /// A share (0..1) shown in per cent with one decimal.
    pub fn percent(self) -> Self {
        Self {
            scale: 100.0,
            decimals: 1,
            ..self
        }
    }

    /// What a JSON null means here (e.g. "above 10 Hz" for a bandwidth not reached).
    pub fn absent(self, absent: &'a str) -> Self {
        Self { absent, ..self }
    }
}

/// A report being assembled; [`HtmlReport::render`] writes the page.
#[derive(Debug)]
pub struct HtmlReport {
    title: String,
    command: String,
    made: Provenance,
    setup: Vec<(String, String)>,
    rows: Vec<Row>,
    tables: Vec<Table>,
    printed: Option<String>,
    figures: Vec<Figure>,
}

impl HtmlReport {
    /// A report titled `title`, with this process's command line.
    pub fn new(title: &str) -> Self {
        Self {
            title: title.to_string(),
            command: command_line(),
            made: Provenance::now(),
            setup: Vec::new(),
            rows: Vec::new(),
            tables: Vec::new(),
            printed: None,
            figures: Vec::new(),
        }
    }

    /// A line of the set-up (controller, plant, rig, log, ...).
    pub fn setup(mut self, name: &str, value: &str) -> Self {
        self.setup.push((name.to_string(), value.to_string()));
        self
    }

    /// The numbers `nums` of `json`, one row each. A JSON null (an option the run did not
    /// reach, e.g. no -3 dB point) reads as the row's `absent` text; a pointer that is not there
    /// reads "missing" rather than a plausible number.
    pub fn numbers(mut self, json: &Value, nums: &[Num]) -> Self {
        for n in nums {
            let value = match json.pointer(n.pointer) {
                Some(Value::Number(x)) => match x.as_f64() {
                    Some(x) => format!("{:.*}", n.decimals, x * n.scale),
                    None => "missing".to_string(),
                },
                Some(Value::Null) => n.absent.to_string(),
                Some(other) => other.to_string(),
                None => "missing".to_string(),
            };
            self.rows.push(Row {
                name: n.name.to_string(),
                value,
                unit: n.unit.to_string(),
                pointer: n.pointer.to_string(),
                numeric: true,
            });
        }
        self
    }

    /// The text at `pointer` in `json` (a string as is; a list of strings joined by " + ",
    /// `empty` when it has none).
    pub fn text(mut self, name: &str, json: &Value, pointer: &str, empty: &str) -> Self {
        let value = match json.pointer(pointer) {
            Some(Value::String(s)) => s.clone(),
            Some(Value::Array(items)) if items.is_empty() => empty.to_string(),
            Some(Value::Array(items)) => items
                .iter()
                .map(|v| v.as_str().map_or_else(|| v.to_string(), str::to_string))
                .collect::<Vec<_>>()
                .join(" + "),
            Some(Value::Null) => empty.to_string(),
            Some(other) => other.to_string(),
            None => "missing".to_string(),
        };
        self.rows.push(Row {
            name: name.to_string(),
            value,
            unit: String::new(),
            pointer: pointer.to_string(),
            numeric: false,
        });
        self
    }

    /// A further table under the figures.
    pub fn table(mut self, caption: &str, header: &[&str], rows: Vec<Vec<String>>) -> Self {
        self.tables.push(Table {
            caption: caption.to_string(),
            header: header.iter().map(|h| h.to_string()).collect(),
            rows,
        });
        self
    }

    /// What the command printed, shown as is (monospaced).
    pub fn printed(mut self, text: &str) -> Self {
        self.printed = Some(text.to_string());
        self
    }

    /// A picture, the SVG document the `--plots` option writes to a file, inlined.
    pub fn figure(mut self, caption: &str, svg: &str) -> Self {
        let prefix = format!("fig{}-", self.figures.len() + 1);
        self.figures.push(Figure {
            caption: caption.to_string(),
            svg: inline_svg(svg, &prefix),
        });
        self
    }

    /// The page.
    pub fn render(&self) -> String {
        let mut h = String::with_capacity(
            64 * 1024 + self.figures.iter().map(|f| f.svg.len()).sum::<usize>(),
        );
        let title = escape(&self.title);
        // Writing to a String cannot fail.
        let _ = write!(
            h,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <title>{title}</title>\n<style>\n{STYLE}</style>\n</head>\n<body>\n<h1>{title}</h1>\n\
             <p class=\"cmd\"><code>{}</code></p>\n<p class=\"made\">{}</p>\n",
            escape(&self.command),
            escape(&self.made.line())
        );
        if !self.setup.is_empty() {
            h.push_str("<table class=\"setup\">\n");
            for (name, value) in &self.setup {
                let _ = writeln!(
                    h,
                    "<tr><th>{}</th><td>{}</td></tr>",
                    escape(name),
                    escape(value)
                );
            }
            h.push_str("</table>\n");
        }
        h.push_str(
            "<h2>Figures</h2>\n<table class=\"figures\">\n\
             <tr><th>quantity</th><th>value</th><th>unit</th></tr>\n",
        );
        for r in &self.rows {
            let data = format!(" data-json=\"{}\"", escape(&r.pointer));
            let class = if r.numeric { " class=\"num\"" } else { "" };
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td{class}{data}>{}</td><td>{}</td></tr>",
                escape(&r.name),
                escape(&r.value),
                escape(&r.unit)
            );
        }
        h.push_str("</table>\n");
        for t in &self.tables {
            let _ = write!(
                h,
                "<h2>{}</h2>\n<table class=\"figures\">\n<tr>",
                escape(&t.caption)
            );
            for c in &t.header {
                let _ = write!(h, "<th>{}</th>", escape(c));
            }
            h.push_str("</tr>\n");
            for row in &t.rows {
                h.push_str("<tr>");
                for c in row {
                    let _ = write!(h, "<td>{}</td>", escape(c));
                }
                h.push_str("</tr>\n");
            }
            h.push_str("</table>\n");
        }
        for f in &self.figures {
            let _ = write!(
                h,
                "<figure>\n{}<figcaption>{}</figcaption>\n</figure>\n",
                f.svg,
                escape(&f.caption)
            );
        }
        if let Some(text) = &self.printed {
            let _ = write!(h, "<h2>Printed output</h2>\n<pre>{}</pre>\n", escape(text));
        }
        let _ = write!(
            h,
            "<p class=\"foot\">host-sim {}</p>\n</body>\n</html>\n",
            env!("CARGO_PKG_VERSION")
        );
        h
    }

    /// Writes the page to `path`, creating missing parent directories.
    pub fn save(&self, path: &Path) -> Result<(), String> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        std::fs::write(path, self.render()).map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// An SVG document as an element of the page: an XML declaration or doctype, which HTML does
/// not allow inside `<body>`, is dropped. Its ids get `prefix`: ids are the whole page's, and
/// every picture numbers its clip paths from `clip0`, so without it the second picture's
/// curves would be clipped to the first one's plot areas.
fn inline_svg(svg: &str, prefix: &str) -> String {
    match svg.find("<svg") {
        Some(start) => svg[start..]
            .replace(" id=\"", &format!(" id=\"{prefix}"))
            .replace("url(#", &format!("url(#{prefix}"))
            .replace("href=\"#", &format!("href=\"#{prefix}")),
        // Not an SVG document: shown as text, never injected as markup.
        None => format!("<pre>{}</pre>\n", escape(svg)),
    }
}

/// Plain and readable, nothing loaded: the system's own sans-serif font.
const STYLE: &str = "body { font-family: sans-serif; max-width: 1100px; margin: 1em auto; \
padding: 0 1em; color: #222; }\n\
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 1.5em; }\n\
table { border-collapse: collapse; margin: 0.5em 0; }\n\
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; }\n\
td.num { text-align: right; font-variant-numeric: tabular-nums; }\n\
p.cmd code { background: #f4f4f4; padding: 0.2em 0.4em; word-break: break-all; }\n\
figure { margin: 1em 0; } figure svg { max-width: 100%; height: auto; }\n\
figcaption { color: #555; font-size: 0.9em; }\n\
pre { background: #f8f8f8; padding: 0.6em; overflow-x: auto; font-size: 0.85em; }\n\
p.foot { color: #888; font-size: 0.8em; }\n";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates_are_the_calendar_s() {
        assert_eq!(utc_date(0), "1970-01-01 00:00:00 UTC");
        assert_eq!(utc_date(951_782_400), "2000-02-29 00:00:00 UTC");
        assert_eq!(utc_date(1_700_000_000), "2023-11-14 22:13:20 UTC");
        assert_eq!(utc_date(4_102_444_799), "2099-12-31 23:59:59 UTC");
    }

    #[test]
    fn text_is_escaped_everywhere() {
        let json = serde_json::json!({ "x": 1.25, "s": "<b>&" });
        let page = HtmlReport::new("a <title> & \"more\"")
            .setup("plant", "<script>alert(1)</script>")
            .numbers(&json, &[num("x", "/x", "deg").decimals(1)])
            .text("s", &json, "/s", "-")
            .printed("a < b")
            .render();
        assert!(page.contains("<title>a &lt;title&gt; &amp; &quot;more&quot;</title>"));
        assert!(!page.contains("<script>"));
        assert!(page.contains("&lt;b&gt;&amp;"));
        assert!(page.contains("a &lt; b"));
    }

    #[test]
    fn numbers_come_from_the_json_and_a_missing_one_says_so() {
        let json = serde_json::json!({ "a": { "gof": 0.5312 }, "bw": null });
        let page = HtmlReport::new("t")
            .numbers(
                &json,
                &[
                    num("GoF", "/a/gof", "%").percent(),
                    num("bandwidth", "/bw", "Hz").absent("above 10 Hz"),
                    num("nothing", "/nope", "Hz"),
                ],
            )
            .render();
        assert!(page.contains("data-json=\"/a/gof\">53.1</td>"));
        assert!(page.contains("data-json=\"/bw\">above 10 Hz</td>"));
        assert!(page.contains("data-json=\"/nope\">missing</td>"));
    }

    #[test]
    fn a_non_svg_picture_is_shown_as_text_not_markup() {
        let page = HtmlReport::new("t")
            .figure("a", "<?xml version=\"1.0\"?>\n<svg></svg>")
            .figure("b", "<img src=x>")
            .render();
        assert!(page.contains("<figure>\n<svg></svg>"));
        assert!(!page.contains("<?xml"));
        assert!(page.contains("&lt;img src=x&gt;"));
    }

    #[test]
    fn ids_are_unique_across_pictures() {
        let svg = "<svg><clipPath id=\"clip0\"/><g clip-path=\"url(#clip0)\"/></svg>";
        let page = HtmlReport::new("t")
            .figure("a", svg)
            .figure("b", svg)
            .render();
        assert!(page.contains("id=\"fig1-clip0\"/><g clip-path=\"url(#fig1-clip0)\""));
        assert!(page.contains("id=\"fig2-clip0\"/><g clip-path=\"url(#fig2-clip0)\""));
        assert!(!page.contains("\"clip0\""));
    }

    #[test]
    fn shell_quoting_round_trips_spaces_and_quotes() {
        assert_eq!(shell_quote("--json"), "--json");
        assert_eq!(shell_quote("a b"), "'a b'");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
        assert_eq!(shell_quote(""), "''");
    }
}
