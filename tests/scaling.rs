//! The sharded runs as a CI matrix (docs/ci/sharded.yml) and as a Slurm job array
//! (scripts/slurm/shards.sbatch), checked as far as that works without GitHub or Slurm:
//! the workflow parses and its matrices agree with the shard counts of their commands;
//! the sbatch script passes `bash -n`, Slurm sees all its `#SBATCH` lines, and it runs a
//! real 2-task array of `report --quick` and its merge when given the array's variables.

use std::path::Path;
use std::process::Command;
use yaml_rust2::{Yaml, YamlLoader};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The `run` lines of a job's steps.
fn runs(job: &Yaml) -> Vec<String> {
    job["steps"]
        .as_vec()
        .expect("steps")
        .iter()
        .filter_map(|s| s["run"].as_str().map(str::to_string))
        .collect()
}

/// The matrix values of `key`, which must be 1 to N; returns N.
fn matrix_count(job: &Yaml, key: &str) -> usize {
    let values: Vec<i64> = job["strategy"]["matrix"][key]
        .as_vec()
        .unwrap_or_else(|| panic!("matrix {key}"))
        .iter()
        .map(|v| v.as_i64().expect("a number"))
        .collect();
    let n = values.len();
    assert_eq!(values, (1..=n as i64).collect::<Vec<_>>(), "{key}: 1 to N");
    n
}

#[test]
fn the_ci_matrix_workflow_parses_and_its_shards_add_up() {
    let text = std::fs::read_to_string(root().join("docs/ci/sharded.yml")).unwrap();
    let docs = YamlLoader::load_from_str(&text).expect("valid YAML");
    let jobs = &docs[0]["jobs"];
    assert!(jobs.as_hash().is_some(), "no jobs");

    let tests = &jobs["tests"];
    let n = matrix_count(tests, "partition");
    assert!(n > 1);
    let partition = format!("--partition count:${{{{ matrix.partition }}}}/{n}");
    assert!(
        runs(tests)
            .iter()
            .any(|r| r.starts_with("cargo nextest run --workspace") && r.contains(&partition)),
        "{:?}",
        runs(tests)
    );

    for (shard_job, merge_job, seeds) in [
        ("report-shard", "report", false),
        ("synth-shard", "synth", true),
    ] {
        let shard = &jobs[shard_job];
        let n = matrix_count(shard, "shard");
        let command = runs(shard)
            .into_iter()
            .find(|r| r.contains("--shard"))
            .unwrap_or_else(|| panic!("{shard_job}: no --shard command"));
        assert!(
            command.contains(&format!("--shard ${{{{ matrix.shard }}}}/{n}")),
            "{command}"
        );
        if seeds {
            let seeds: usize = command
                .split("--seeds ")
                .nth(1)
                .and_then(|s| s.split(' ').next())
                .and_then(|s| s.parse().ok())
                .expect("--seeds N");
            assert!(seeds >= n, "{seeds} seeds over {n} shards");
        }
        let merge = &jobs[merge_job];
        assert_eq!(
            merge["needs"].as_str(),
            Some(shard_job),
            "{merge_job} waits for every shard"
        );
        assert!(
            runs(merge).iter().any(|r| r.contains("--merge")),
            "{merge_job}"
        );
    }
}

#[test]
fn the_slurm_array_script_is_valid_and_runs_a_sharded_quick_report() {
    let script = root().join("scripts/slurm/shards.sbatch");
    let out = Command::new("bash")
        .arg("-n")
        .arg(&script)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // sbatch reads #SBATCH lines only up to the first command
    let text = std::fs::read_to_string(&script).unwrap();
    let first_command = text
        .lines()
        .position(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .unwrap();
    let directives: Vec<usize> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("#SBATCH"))
        .map(|(i, _)| i)
        .collect();
    assert!(!directives.is_empty());
    assert!(
        directives.iter().all(|&i| i < first_command),
        "an #SBATCH line after a command"
    );

    let shards = std::env::temp_dir().join(format!("skinbox-slurm-{}", std::process::id()));
    std::fs::remove_dir_all(&shards).ok();
    let task = |mode: &str, id: Option<u32>| {
        let mut c = Command::new("bash");
        c.arg(&script)
            .args([mode, "--quick"])
            .env("SHARDS", &shards)
            .env("SKINBOX_BIN", env!("CARGO_BIN_EXE_skinbox"))
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("SLURM_ARRAY_TASK_COUNT");
        if let Some(id) = id {
            c.env("SLURM_ARRAY_TASK_ID", id.to_string())
                .env("SLURM_ARRAY_TASK_COUNT", "2");
        }
        c.output().unwrap()
    };
    let out = task("report", None);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("run as a job array"), "{stderr}");

    for id in [1, 2] {
        let out = task("report", Some(id));
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(shards
            .join(format!("shard-{id}/points-{id}-of-2.jsonl"))
            .is_file());
    }
    let out = task("report-merge", None);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = std::fs::read_to_string(shards.join("report/summary.md")).unwrap();
    assert!(
        summary.contains("`skinbox report --quick`, merged from 2 shards"),
        "{summary}"
    );
    for id in ["C1", "C2", "C3", "C4a", "C4b", "C4c", "C4d"] {
        assert!(summary.contains(&format!("\n## {id} ")), "{id}");
    }
    std::fs::remove_dir_all(&shards).ok();
}
