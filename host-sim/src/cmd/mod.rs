//! The binary's subcommands, one file each (`gap` and `identify` live in the library,
//! `host_sim::gap::cli`), and the output helpers they share. Data flows one way: `main.rs`
//! parses and dispatches into these modules, which use `common` and the helpers here.

use std::path::Path;

/// `println!` that ends the program quietly when stdout is closed (`host-sim ... | head`)
/// instead of panicking on the broken pipe.
macro_rules! say {
    ($($arg:tt)*) => {
        host_sim::out::stdout_line("host-sim", format_args!($($arg)*))
    };
}
pub(crate) use say;

pub(crate) mod bench;
pub(crate) mod common;
pub(crate) mod limits;
pub(crate) mod poles;
pub(crate) mod step;
pub(crate) mod sweep;
pub(crate) mod track;

pub(crate) type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Writes `value` as pretty JSON to `path`, creating missing parent directories.
pub(crate) fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").map_err(|e| format!("{}: {e}", path.display()))?;
    say!("figures written to {}", path.display());
    Ok(())
}

/// Saves one picture as `dir/name` and says where.
pub(crate) fn save_svg(
    dir: &Path,
    name: &str,
    svg_save: impl FnOnce(&Path) -> std::io::Result<()>,
) -> Result<()> {
    let path = dir.join(name);
    svg_save(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    say!("picture written to {}", path.display());
    Ok(())
}
