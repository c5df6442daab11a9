//! The model cache across processes: two processes (as under cargo-nextest, or shards of
//! a CI matrix sharing a cache) that need the same model at once build it once; the other
//! waits for the first and loads the same library.

use skinbox_cosim::frames::{assemble, check};
use skinbox_cosim::{Dut, Model};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::DatagramRepr;
use std::os::unix::fs::MetadataExt;
use std::process::{Command, Stdio};

/// What [`one_port_box_loads_and_sends_its_boot_status`] prints about its model.
const MARK: &str = "cached model:";
const CHILD_TEST: &str = "one_port_box_loads_and_sends_its_boot_status";

/// Builds (or loads) the 1-port box from the cache of `$SKINBOX_BUILD_DIR` (or the
/// workspace's), checks that it runs, and prints which library it loaded and whether it
/// built it. The test below runs it as a child process twice at once.
#[test]
fn one_port_box_loads_and_sends_its_boot_status() {
    let config = BoxConfig {
        ports: 1,
        ..BoxConfig::default()
    };
    let model = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let mut dut = Dut::new(&model, None).unwrap();
    let mut out = vec![];
    dut.set_reset(true);
    dut.run(3, |b| out.push(b));
    dut.set_reset(false);
    dut.run(5_000, |b| out.push(b));
    let (frames, _) = assemble(&out);
    assert_eq!(frames.len(), 1, "one status datagram after reset");
    let datagram = DatagramRepr::parse(check(&frames[0].bytes).unwrap().1).unwrap();
    assert!(matches!(datagram.body, DatagramBody::Status(_)));
    let inode = std::fs::metadata(model.library_path()).unwrap().ino();
    println!(
        "{MARK} {} inode {inode} built {}",
        model.library_path().display(),
        model.was_built()
    );
}

#[test]
fn two_processes_building_the_same_model_at_once_build_it_once() {
    let build_dir =
        std::env::temp_dir().join(format!("skinbox-cache-procs-{}", std::process::id()));
    std::fs::remove_dir_all(&build_dir).ok();
    let spawn = || {
        Command::new(std::env::current_exe().unwrap())
            .args(["--exact", CHILD_TEST, "--nocapture", "--test-threads", "1"])
            .env("SKINBOX_BUILD_DIR", &build_dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start the test binary")
    };
    let children = [spawn(), spawn()];
    let mut seen = Vec::new();
    for child in children {
        let out = child.wait_with_output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let line = stdout
            .lines()
            .find_map(|l| l.split_once(MARK).map(|(_, rest)| rest))
            .unwrap_or_else(|| panic!("no '{MARK}' line in:\n{stdout}"));
        let words: Vec<&str> = line.split_whitespace().collect();
        assert_eq!((words[1], words[3]), ("inode", "built"), "{line}");
        seen.push((
            words[0].to_string(),
            words[2].to_string(),
            words[4] == "true",
        ));
    }
    let cache = build_dir.join("verilated");
    assert!(
        seen[0].0.starts_with(cache.to_str().unwrap()),
        "{seen:?} not in {}",
        cache.display()
    );
    assert_eq!(seen[0].0, seen[1].0, "the same library");
    assert_eq!(
        seen[0].1, seen[1].1,
        "the same file, not a second build over it"
    );
    assert_eq!(
        seen.iter().filter(|s| s.2).count(),
        1,
        "exactly one process built the model: {seen:?}"
    );
    // one model entry and the runtime, no scratch directory left behind
    let mut entries: Vec<String> = std::fs::read_dir(&cache)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.ends_with(".lock"))
        .collect();
    entries.sort();
    assert_eq!(entries.len(), 2, "{entries:?}");
    assert!(
        entries[0].starts_with("box1-") && !entries[0].contains(".tmp"),
        "{entries:?}"
    );
    assert!(entries[1].starts_with("runtime-"), "{entries:?}");
    std::fs::remove_dir_all(&build_dir).ok();
}
