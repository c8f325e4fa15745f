//! `--report out.html` of `sweep`, `track` and `gap`, run through the real binary: one
//! well-formed page with every picture `--plots` writes inlined, nothing linked from the
//! network, and a table whose numbers are the ones `--json` writes and the command prints.

#![allow(clippy::unwrap_used)] // test helpers: a failed unwrap is a failed test
use std::path::Path;
use std::process::{Command, Output};

fn host_sim(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(args)
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Elements HTML writes without a closing tag.
const VOID: &[&str] = &["meta", "br", "hr", "img", "input", "link", "wbr"];

/// The page's tags balance: every element opened is closed in order (SVG's `<x/>` closes
/// itself), and the document is one `<html>` with `<head>` and `<body>`. Text between tags
/// must hold no `<` (escaped text never does).
fn assert_balanced(html: &str) {
    assert!(html.starts_with("<!DOCTYPE html>"), "no doctype");
    let mut stack: Vec<String> = Vec::new();
    let mut top_level = Vec::new();
    let mut rest = &html["<!DOCTYPE html>".len()..];
    while let Some(open) = rest.find('<') {
        let close = open + rest[open..].find('>').expect("a tag is closed by >");
        let tag = &rest[open + 1..close];
        rest = &rest[close + 1..];
        let name: String = tag
            .trim_start_matches('/')
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        assert!(!name.is_empty(), "not a tag: <{tag}>");
        if let Some(closing) = tag.strip_prefix('/') {
            let expected = stack
                .pop()
                .unwrap_or_else(|| panic!("</{closing}> closes nothing"));
            assert_eq!(closing.trim(), expected, "</{closing}> closes <{expected}>");
        } else if !(tag.ends_with('/') || VOID.contains(&name.as_str())) {
            if stack.len() <= 1 {
                top_level.push(name.clone());
            }
            stack.push(name);
        }
    }
    assert!(stack.is_empty(), "left open: {stack:?}");
    assert_eq!(top_level, ["html", "head", "body"]);
}

/// Nothing to fetch: no `src`/`href` reaching the network, no stylesheet or script links.
fn assert_self_contained(html: &str) {
    let lower = html.to_ascii_lowercase();
    for attr in ["src=", "href="] {
        for (at, _) in lower.match_indices(attr) {
            let value = lower[at + attr.len()..].trim_start_matches(['"', '\'']);
            assert!(
                !value.starts_with("http://")
                    && !value.starts_with("https://")
                    && !value.starts_with("//"),
                "a network reference: {}",
                &html[at..(at + 80).min(html.len())]
            );
        }
    }
    assert!(!lower.contains("<link"), "a linked resource");
    assert!(!lower.contains("<script"), "a script");
    assert!(!lower.contains("@import"), "a CSS import");
    assert!(
        lower.matches("url(").count() == lower.matches("url(#").count(),
        "a url() outside the page"
    );
}

/// Every id once in the page (the pictures' clip paths included), and every `url(#id)` one of
/// them, so no picture draws with another one's clip path.
fn assert_ids_unique(html: &str) {
    let ids: Vec<&str> = html
        .split(" id=\"")
        .skip(1)
        .map(|s| &s[..s.find('"').unwrap()])
        .collect();
    let mut unique = ids.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), ids.len(), "repeated ids");
    for r in html.split("url(#").skip(1) {
        let id = &r[..r.find(')').unwrap()];
        assert!(ids.contains(&id), "url(#{id}) names no element");
    }
}

/// Every SVG file `--plots` wrote is in the page, whole; and the page has no other picture.
fn assert_figures_inline(html: &str, plots: &Path, expected: usize) {
    let mut files: Vec<_> = std::fs::read_dir(plots)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .collect();
    files.sort();
    assert_eq!(files.len(), expected, "pictures written: {files:?}");
    // The page prefixes each picture's ids (`fig2-clip0`); without the prefixes the pictures
    // are the files, byte for byte.
    let mut unprefixed = html.to_string();
    for n in 1..=files.len() {
        unprefixed = unprefixed.replace(&format!("\"fig{n}-"), "\"");
        unprefixed = unprefixed.replace(&format!("#fig{n}-"), "#");
    }
    for f in &files {
        let svg = std::fs::read_to_string(f).unwrap();
        assert!(svg.trim_start().starts_with("<svg"), "{}", f.display());
        assert!(
            unprefixed.contains(svg.trim_end()),
            "{} is not inlined in the report",
            f.display()
        );
    }
    assert_eq!(html.matches("<svg").count(), files.len());
    assert_eq!(html.matches("</svg>").count(), files.len());
}

/// The table cell read from JSON pointer `pointer`.
fn cell<'a>(html: &'a str, pointer: &str) -> &'a str {
    let key = format!("data-json=\"{pointer}\">");
    let at = html
        .find(&key)
        .unwrap_or_else(|| panic!("no table cell for {pointer}"))
        + key.len();
    &html[at..at + html[at..].find('<').unwrap()]
}

/// The cell for `pointer` shows the JSON's number times `scale` to `decimals` places.
fn assert_cell_is(html: &str, json: &serde_json::Value, pointer: &str, scale: f64, decimals: i32) {
    let expected = json
        .pointer(pointer)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or_else(|| panic!("the JSON has no number at {pointer}"));
    let shown: f64 = cell(html, pointer)
        .parse()
        .unwrap_or_else(|_| panic!("{pointer}: {:?} is not a number", cell(html, pointer)));
    let half_step = 0.5 * 10f64.powi(-decimals) + 1e-9;
    assert!(
        (shown - expected * scale).abs() <= half_step,
        "{pointer}: table {shown}, JSON {expected} (x {scale})"
    );
}

/// `host-sim ARGS --report --json --plots` into `dir`: what it printed, the page, the JSON
/// and the pictures' directory.
fn run_with_outputs(
    dir: &Path,
    args: &[&str],
) -> (String, String, serde_json::Value, std::path::PathBuf) {
    let (report, json, plots) = (
        dir.join("out/report.html"),
        dir.join("figures.json"),
        dir.join("plots"),
    );
    let mut all = args.to_vec();
    all.extend([
        "--report",
        report.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--plots",
        plots.to_str().unwrap(),
    ]);
    let out = host_sim(&all);
    let html = std::fs::read_to_string(&report).unwrap();
    let printed = String::from_utf8_lossy(&out.stdout).into_owned();
    (printed, html, read_json(&json), plots)
}

fn check_page(html: &str, plots: &Path, figures: usize) {
    assert_balanced(html);
    assert_self_contained(html);
    assert_ids_unique(html);
    assert_figures_inline(html, plots, figures);
}

#[test]
fn sweep_report_holds_the_bode_and_time_figures_and_the_json_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let (printed, html, v, plots) = run_with_outputs(dir.path(), &["sweep", "--duration-s", "4"]);
    check_page(&html, &plots, 2);
    assert!(html.contains("<title>host-sim sweep: Sine sweep 0-10 Hz, 10 deg at the wheel"));
    assert!(html.contains("--duration-s 4 --report"), "no command line");
    // The command by the program's name, not the build directory's path; and what made it.
    assert!(
        html.contains("<code>host-sim sweep --duration-s 4"),
        "the command is not `host-sim ...`"
    );
    assert!(
        !html.contains(env!("CARGO_BIN_EXE_host-sim")),
        "absolute path"
    );
    let made = &html[html
        .find("<p class=\"made\">made ")
        .expect("no date, host, commit")..];
    let made = &made[..made.find("</p>").unwrap()];
    assert!(
        made.contains(" UTC on ") && made.contains(" at commit "),
        "{made}"
    );
    assert!(html.contains("paper mode: Hall feedback"), "no controller");
    for (pointer, decimals) in [
        ("/bandwidth_hz", 2),
        ("/bandwidth_bound_hz", 2),
        ("/small_signal_bandwidth_hz", 2),
        ("/tracking/rmse", 2),
        ("/max_current_a", 2),
    ] {
        assert_cell_is(&html, &v, pointer, 1.0, decimals);
    }
    // The printed bandwidth is the table's.
    let bw = cell(&html, "/bandwidth_hz");
    assert!(
        printed.contains(&format!("-3 dB bandwidth    {bw:>6} Hz")),
        "printed: {printed}"
    );
}

#[test]
fn track_report_escapes_the_reference_name_and_holds_the_rmse() {
    let dir = tempfile::tempdir().unwrap();
    // A file name with HTML's special characters: they must reach the page as text.
    let csv = dir.path().join("ref <b>&'x'.csv");
    let mut text = String::from("t,ref_sw_deg\n");
    for k in 0..=300 {
        let t = k as f64 * 0.01;
        text += &format!(
            "{t:.2},{:.4}\n",
            8.0 * (std::f64::consts::TAU * 0.5 * t).sin()
        );
    }
    std::fs::write(&csv, text).unwrap();
    let (printed, html, v, plots) = run_with_outputs(
        dir.path(),
        &[
            "track",
            "--csv",
            csv.to_str().unwrap(),
            "--controller",
            "ecu",
        ],
    );
    check_page(&html, &plots, 1);
    assert!(!html.contains("<b>"), "the file name went in as markup");
    assert!(html.contains("ref &lt;b&gt;&amp;&#39;x&#39;.csv"));
    assert!(html.contains("ECU mode"), "no controller");
    for pointer in ["/rmse_deg", "/max_error_deg", "/max_voltage_v"] {
        assert_cell_is(&html, &v, pointer, 1.0, 2);
    }
    let rmse = cell(&html, "/rmse_deg");
    assert!(printed.contains(&format!("RMSE               {rmse:>6} deg")));
}

#[test]
fn gap_report_of_a_step_log_holds_the_verdict_and_gof_of_the_json() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("step.csv");
    host_sim(&["step", "--log", log.to_str().unwrap()]);
    let (printed, html, v, plots) = run_with_outputs(
        dir.path(),
        &["gap", log.to_str().unwrap(), "--threads", "2"],
    );
    // A 1.5 s step is too short for the Bode estimate; the log has the motor angle, so the
    // residual and the segment replay.
    check_page(&html, &plots, 2);
    assert_cell_is(&html, &v, "/baseline_gof", 100.0, 1);
    assert_cell_is(&html, &v, "/verdict/gof_after", 100.0, 1);
    assert_cell_is(&html, &v, "/simulations", 1.0, 0);
    assert!(html.contains("<figcaption>Segment replay"));
    assert_eq!(
        cell(&html, "/verdict/kind"),
        v["verdict"]["kind"].as_str().unwrap()
    );
    let ranked = v["ranking"].as_array().unwrap();
    assert!(!ranked.is_empty());
    for c in ranked {
        let effect = c["effect"].as_str().unwrap();
        assert!(
            html.contains(&format!("<tr><td>{effect}</td>")),
            "{effect} not ranked"
        );
    }
    // What the command printed is in the page, escaped (`motor->steering`).
    let first = printed.lines().next().unwrap();
    assert!(html.contains(first), "{first}");
    assert!(html.contains("motor-&gt;steering"));
}

#[test]
fn gap_selftest_and_bench_refuse_report_instead_of_ignoring_it() {
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("x.html");
    for mode in ["selftest", "bench"] {
        let out = Command::new(env!("CARGO_BIN_EXE_host-sim"))
            .args(["gap", mode, "--report", page.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(!out.status.success(), "gap {mode} --report succeeded");
        assert!(String::from_utf8_lossy(&out.stderr).contains("--report"));
        assert!(!page.exists());
    }
}
