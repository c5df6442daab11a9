//! `skinbox wireshark`: the Lua dissector for Wireshark and tshark, generated from the
//! protocol crate; written to a file, to the user's plugin folder, or to standard output.

use anyhow::Context;
use serde::Serialize;
use skinbox_host::wireshark::{dissector_lua, personal_plugin_dir, PLUGIN_FILE};
use std::path::PathBuf;

/// Arguments of `skinbox wireshark`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Write the plugin to this file (standard output when neither this nor --install).
    #[arg(short, long, conflicts_with = "install")]
    output: Option<PathBuf>,
    /// Install the plugin in Wireshark's personal Lua plugin folder
    /// (~/.local/lib/wireshark/plugins), where Wireshark and tshark load it at start.
    #[arg(long)]
    install: bool,
}

#[derive(Serialize)]
struct Written {
    path: PathBuf,
    bytes: usize,
}

/// Writes the plugin where asked.
pub fn run(args: &Args, json: bool) -> anyhow::Result<()> {
    let lua = dissector_lua();
    let path = if args.install {
        let dir = personal_plugin_dir()
            .context("no home folder (HOME is not set): use --output FILE instead")?;
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        Some(dir.join(PLUGIN_FILE))
    } else {
        args.output.clone()
    };
    let Some(path) = path else {
        print!("{lua}");
        return Ok(());
    };
    std::fs::write(&path, &lua).with_context(|| format!("writing {}", path.display()))?;
    let written = Written {
        path,
        bytes: lua.len(),
    };
    if json {
        super::print_json(&written)?;
    } else {
        println!(
            "wrote the skinbox dissector to {} ({} bytes); Wireshark and tshark load it at their next start{}",
            written.path.display(),
            written.bytes,
            if args.install {
                ""
            } else {
                " with -X lua_script:FILE"
            }
        );
    }
    Ok(())
}
