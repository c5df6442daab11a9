//! The points of the studies' grids, and how a report is split into shards and merged.
//!
//! Every study computes each point of its grid through [`Points::run`] with a key that
//! names it (`C1/idle/1`). The points are numbered in the order the studies ask for them,
//! which depends only on `--quick` (the grids), never on results; a search in which a
//! point depends on an earlier one's result must be one point (one `run` call).
//!
//! - [`Points::all`]: an ordinary run computes every point.
//! - [`Points::shard`]: shard `K/N` computes the points whose number `i` has
//!   `i % N == K - 1` and hands the studies `T::default()` for the others; its summary and
//!   charts are meaningless and not written, only its rows ([`ShardFile`]).
//! - [`Points::replay`]: a merge computes nothing: every point's result comes from the
//!   shards' rows, so the summary and charts are those of an unsharded run. Measured
//!   wall times are the ones of the shard that ran the point.
//!
//! Every result goes through JSON in every mode (serde_json with `float_roundtrip`, so
//! floats come back bit for bit), so a merged report equals an unsharded one number for
//! number.

use anyhow::{anyhow, bail, Context};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashSet};
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// One share of a sharded run: shard `index` of `count`, both counted from 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This shard, 1 to `count`.
    pub index: u32,
    /// Shards in all.
    pub count: u32,
}

impl Shard {
    /// Whether point number `i` (from 0) belongs to this shard.
    pub fn owns(&self, i: usize) -> bool {
        i % self.count as usize == (self.index - 1) as usize
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = String;

    /// `K/N` with `1 <= K <= N`, as a CI matrix or a Slurm array index gives it.
    fn from_str(s: &str) -> Result<Shard, String> {
        let bad =
            |why: &str| format!("--shard {s:?}: {why}; expected K/N with 1 <= K <= N, e.g. 2/3");
        let (k, n) = s.split_once('/').ok_or_else(|| bad("no '/'"))?;
        let k: u32 = k.trim().parse().map_err(|_| bad("K is not a number"))?;
        let n: u32 = n.trim().parse().map_err(|_| bad("N is not a number"))?;
        if n == 0 {
            return Err(bad("N is 0"));
        }
        if k == 0 || k > n {
            return Err(bad(&format!(
                "K is {k}, outside 1 to {n} (shards count from 1)"
            )));
        }
        Ok(Shard { index: k, count: n })
    }
}

/// One point's result as a shard writes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Its number in the grid, from 0.
    pub index: usize,
    /// Its key.
    pub key: String,
    /// The result.
    pub value: serde_json::Value,
    /// Wall time of its computation, s.
    #[serde(default)]
    pub seconds: f64,
}

/// What a shard writes: `points-K-of-N.jsonl`, a header line and then one [`Row`] a line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardHeader {
    /// What the file is: [`ShardHeader::KIND`].
    pub kind: String,
    /// Which shard.
    pub shard: Shard,
    /// Whether the shard ran `--quick`.
    pub quick: bool,
    /// Points in the whole grid.
    pub points: usize,
    /// A digest of every key of the grid, in order: shards of the same grid agree on it.
    pub grid: String,
    /// The shard's wall time, s.
    pub wall_s: f64,
}

impl ShardHeader {
    /// The `kind` of a shard file of `skinbox report`.
    pub const KIND: &'static str = "skinbox report shard";
}

/// A shard's file: header and rows.
#[derive(Debug, Clone, PartialEq)]
pub struct ShardFile {
    /// The header.
    pub header: ShardHeader,
    /// The points it computed.
    pub rows: Vec<Row>,
}

impl ShardFile {
    /// The file name of `shard`: `points-K-of-N.jsonl`.
    pub fn name(shard: Shard) -> String {
        format!("points-{}-of-{}.jsonl", shard.index, shard.count)
    }

    /// Writes it into `dir` as [`ShardFile::name`]; returns the path.
    pub fn write(&self, dir: &Path) -> anyhow::Result<PathBuf> {
        let mut text = serde_json::to_string(&self.header)?;
        text.push('\n');
        for row in &self.rows {
            text.push_str(&serde_json::to_string(row)?);
            text.push('\n');
        }
        let path = dir.join(Self::name(self.header.shard));
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        Ok(path)
    }

    /// Reads one shard file.
    pub fn read(path: &Path) -> anyhow::Result<ShardFile> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut lines = text.lines();
        let header: ShardHeader = lines
            .next()
            .ok_or_else(|| anyhow!("{}: empty", path.display()))
            .and_then(|l| Ok(serde_json::from_str(l)?))
            .with_context(|| format!("{}: not a shard file of skinbox report", path.display()))?;
        if header.kind != ShardHeader::KIND {
            bail!("{}: not a shard file of skinbox report", path.display());
        }
        let rows = lines
            .enumerate()
            .map(|(n, l)| {
                serde_json::from_str(l)
                    .with_context(|| format!("{} line {}: not a point", path.display(), n + 2))
            })
            .collect::<anyhow::Result<_>>()?;
        Ok(ShardFile { header, rows })
    }

    /// Every shard file (`points-*-of-*.jsonl`) in `dirs`.
    pub fn read_dirs(dirs: &[PathBuf]) -> anyhow::Result<Vec<(PathBuf, ShardFile)>> {
        let mut files = Vec::new();
        for dir in dirs {
            let entries =
                std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))?;
            let mut paths: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                        n.starts_with("points-") && n.ends_with(".jsonl") && n.contains("-of-")
                    })
                })
                .collect();
            if paths.is_empty() {
                bail!(
                    "{}: no shard file (points-K-of-N.jsonl) of `skinbox report --shard`",
                    dir.display()
                );
            }
            paths.sort();
            for p in paths {
                let f = ShardFile::read(&p)?;
                files.push((p, f));
            }
        }
        Ok(files)
    }
}

/// The merged rows of a complete set of shards, checked: one grid, one `--quick`, every
/// shard once, every point once.
#[derive(Debug, Clone)]
pub struct Merged {
    /// Whether the shards ran `--quick`.
    pub quick: bool,
    /// Shards merged.
    pub shards: u32,
    /// The longest shard's wall time, s.
    pub longest_shard_s: f64,
    /// Every point, by number.
    pub rows: Vec<Row>,
    grid: String,
}

impl Merged {
    /// Checks and merges shard files.
    pub fn new(files: Vec<(PathBuf, ShardFile)>) -> anyhow::Result<Merged> {
        let (first_path, first) = files.first().ok_or_else(|| anyhow!("no shard files"))?;
        let h0 = first.header.clone();
        let mut shards: BTreeMap<u32, &Path> = BTreeMap::new();
        for (path, f) in &files {
            let h = &f.header;
            if h.quick != h0.quick {
                bail!(
                    "{} ran {} but {} ran {}: shards of one report run the same grid",
                    first_path.display(),
                    if h0.quick {
                        "with --quick"
                    } else {
                        "without --quick"
                    },
                    path.display(),
                    if h.quick {
                        "with --quick"
                    } else {
                        "without --quick"
                    },
                );
            }
            if h.points != h0.points || h.grid != h0.grid {
                bail!(
                    "{} and {} are shards of different grids ({} and {} points, digests {} and \
                     {}): run every shard with the same version and options",
                    first_path.display(),
                    path.display(),
                    h0.points,
                    h.points,
                    h0.grid,
                    h.grid
                );
            }
            if h.shard.count != h0.shard.count {
                bail!(
                    "{} is shard {} but {} is shard {}: all shards are of one split",
                    first_path.display(),
                    h0.shard,
                    path.display(),
                    h.shard
                );
            }
            if let Some(other) = shards.insert(h.shard.index, path) {
                bail!(
                    "shard {} given twice: {} and {}",
                    h.shard,
                    other.display(),
                    path.display()
                );
            }
        }
        let missing: Vec<String> = (1..=h0.shard.count)
            .filter(|k| !shards.contains_key(k))
            .map(|k| format!("{k}/{}", h0.shard.count))
            .collect();
        if !missing.is_empty() {
            bail!(
                "shard {} missing (have {})",
                missing.join(", "),
                shards
                    .values()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        let mut rows: Vec<Option<Row>> = vec![None; h0.points];
        for (path, f) in &files {
            for row in &f.rows {
                let slot = rows.get_mut(row.index).ok_or_else(|| {
                    anyhow!(
                        "{}: point {} ({}) outside the grid of {} points",
                        path.display(),
                        row.index,
                        row.key,
                        h0.points
                    )
                })?;
                if slot.is_some() {
                    bail!(
                        "{}: point {} ({}) is in more than one shard file",
                        path.display(),
                        row.index,
                        row.key
                    );
                }
                *slot = Some(row.clone());
            }
        }
        let rows = rows
            .into_iter()
            .enumerate()
            .map(|(i, r)| r.ok_or_else(|| anyhow!("point {i} is in no shard file")))
            .collect::<anyhow::Result<_>>()?;
        Ok(Merged {
            quick: h0.quick,
            shards: h0.shard.count,
            longest_shard_s: files
                .iter()
                .map(|(_, f)| f.header.wall_s)
                .fold(0.0, f64::max),
            rows,
            grid: h0.grid,
        })
    }
}

enum Mode {
    All,
    Shard(Shard),
    Replay(Merged),
}

/// The points of a run; see the module documentation.
pub struct Points {
    mode: Mode,
    keys: Vec<String>,
    seen: HashSet<String>,
    rows: Vec<Row>,
}

impl Points {
    fn new(mode: Mode) -> Points {
        Points {
            mode,
            keys: Vec::new(),
            seen: HashSet::new(),
            rows: Vec::new(),
        }
    }

    /// Computes every point.
    pub fn all() -> Points {
        Points::new(Mode::All)
    }

    /// Computes the points of `shard` only.
    pub fn shard(shard: Shard) -> Points {
        Points::new(Mode::Shard(shard))
    }

    /// Computes nothing: every result comes from `merged`.
    pub fn replay(merged: Merged) -> Points {
        Points::new(Mode::Replay(merged))
    }

    /// The result of the point `key`: computed by `compute`, or, for a point of another
    /// shard, `T::default()`, or, in a merge, read from the shards.
    pub fn run<T, F>(&mut self, key: impl Into<String>, compute: F) -> anyhow::Result<T>
    where
        T: Serialize + DeserializeOwned + Default,
        F: FnOnce() -> anyhow::Result<T>,
    {
        let key = key.into();
        let index = self.keys.len();
        if !self.seen.insert(key.clone()) {
            bail!("point key {key} used twice (a study's keys must name each point)");
        }
        self.keys.push(key.clone());
        let value = match &self.mode {
            Mode::Shard(shard) if !shard.owns(index) => return Ok(T::default()),
            Mode::All | Mode::Shard(_) => {
                let started = std::time::Instant::now();
                let value = serde_json::to_value(compute()?)
                    .with_context(|| format!("point {key}: result does not serialise"))?;
                // a shard writes its rows; a whole run only uses the value
                if matches!(self.mode, Mode::Shard(_)) {
                    self.rows.push(Row {
                        index,
                        key: key.clone(),
                        value: value.clone(),
                        seconds: started.elapsed().as_secs_f64(),
                    });
                }
                value
            }
            Mode::Replay(merged) => {
                let row = merged.rows.get(index).ok_or_else(|| {
                    anyhow!(
                        "the shards hold {} points, this grid more (from {key} on): they ran \
                         another version or other options",
                        merged.rows.len()
                    )
                })?;
                if row.key != key {
                    bail!(
                        "point {index} is {} in the shards but {key} here: they ran another \
                         version or other options",
                        row.key
                    );
                }
                row.value.clone()
            }
        };
        serde_json::from_value(value).with_context(|| format!("point {key}: reading its result"))
    }

    /// Points asked for so far.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Whether no point was asked for.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// A digest of every key so far, in order (FNV-1a, 64 bits, hex).
    pub fn grid_digest(&self) -> String {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for key in &self.keys {
            for b in key.bytes().chain([0]) {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        }
        format!("{h:016x}")
    }

    /// The shard, when this run is one.
    pub fn shard_of(&self) -> Option<Shard> {
        match self.mode {
            Mode::Shard(s) => Some(s),
            _ => None,
        }
    }

    /// After the studies: the shard file of a shard run (None otherwise), and, for a merge,
    /// the check that the studies asked for exactly the shards' points.
    pub fn finish(self, quick: bool, wall_s: f64) -> anyhow::Result<Option<ShardFile>> {
        let grid = self.grid_digest();
        match self.mode {
            Mode::All => Ok(None),
            Mode::Shard(shard) => Ok(Some(ShardFile {
                header: ShardHeader {
                    kind: ShardHeader::KIND.into(),
                    shard,
                    quick,
                    points: self.keys.len(),
                    grid,
                    wall_s,
                },
                rows: self.rows,
            })),
            Mode::Replay(merged) => {
                if merged.rows.len() != self.keys.len() || merged.grid != grid {
                    bail!(
                        "the shards hold {} points (grid {}), this version's grid {} (grid {}): \
                         merge with the version that ran them",
                        merged.rows.len(),
                        merged.grid,
                        self.keys.len(),
                        grid
                    );
                }
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_syntax() {
        assert_eq!("2/3".parse(), Ok(Shard { index: 2, count: 3 }));
        assert_eq!("1/1".parse(), Ok(Shard { index: 1, count: 1 }));
        for (bad, why) in [
            ("0/3", "K is 0, outside 1 to 3"),
            ("4/3", "K is 4, outside 1 to 3"),
            ("1/0", "N is 0"),
            ("3", "no '/'"),
            ("a/3", "K is not a number"),
            ("1/b", "N is not a number"),
        ] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn shards_own_every_point_once() {
        let shards: Vec<Shard> = (1..=3).map(|k| Shard { index: k, count: 3 }).collect();
        for i in 0..10 {
            assert_eq!(shards.iter().filter(|s| s.owns(i)).count(), 1, "{i}");
        }
    }

    /// A toy study: squares of 0..n, plus a search whose points depend on each other.
    fn study(points: &mut Points, n: u32) -> anyhow::Result<Vec<f64>> {
        let mut out = Vec::new();
        for x in 0..n {
            out.push(points.run(format!("sq/{x}"), || Ok(f64::from(x).sqrt() / 3.0))?);
        }
        let search: (u32, f64) = points.run("search", || {
            let mut x = 1u32;
            while x * x < 50 {
                x += 1;
            }
            Ok((x, 0.1 + 0.2))
        })?;
        out.push(f64::from(search.0) + search.1);
        Ok(out)
    }

    fn shard_files(count: u32, n: u32) -> Vec<(PathBuf, ShardFile)> {
        (1..=count)
            .map(|k| {
                let mut p = Points::shard(Shard { index: k, count });
                study(&mut p, n).unwrap();
                let f = p.finish(true, 1.0).unwrap().unwrap();
                (PathBuf::from(ShardFile::name(f.header.shard)), f)
            })
            .collect()
    }

    #[test]
    fn merged_shards_replay_the_unsharded_results_bit_for_bit() {
        let mut all = Points::all();
        let expected = study(&mut all, 7).unwrap();
        let merged = Merged::new(shard_files(3, 7)).unwrap();
        let mut replay = Points::replay(merged);
        assert_eq!(study(&mut replay, 7).unwrap(), expected);
        replay.finish(true, 0.0).unwrap();
    }

    #[test]
    fn a_file_round_trips() {
        let (_, f) = shard_files(2, 5).remove(1);
        let dir = std::env::temp_dir().join(format!("skinbox-points-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = f.write(&dir).unwrap();
        assert!(path.ends_with("points-2-of-2.jsonl"));
        assert_eq!(ShardFile::read(&path).unwrap(), f);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn incomplete_or_mixed_shards_are_refused() {
        let mut files = shard_files(3, 7);
        let third = files.remove(2);
        let e = Merged::new(files.clone()).unwrap_err().to_string();
        assert!(e.contains("shard 3/3 missing"), "{e}");

        let mut twice = files.clone();
        twice.push(files[1].clone());
        let e = Merged::new(twice).unwrap_err().to_string();
        assert!(e.contains("shard 2/3 given twice"), "{e}");

        let mut other_grid = files.clone();
        other_grid.push(shard_files(3, 8).remove(2));
        let e = Merged::new(other_grid).unwrap_err().to_string();
        assert!(e.contains("shards of different grids"), "{e}");

        let mut not_quick = files.clone();
        let mut t = third.clone();
        t.1.header.quick = false;
        not_quick.push(t);
        let e = Merged::new(not_quick).unwrap_err().to_string();
        assert!(e.contains("without --quick"), "{e}");

        let mut duplicated = files.clone();
        let mut t = third.clone();
        t.1.rows.push(files[0].1.rows[0].clone());
        duplicated.push(t);
        let e = Merged::new(duplicated).unwrap_err().to_string();
        assert!(e.contains("in more than one shard file"), "{e}");

        let mut lost = files.clone();
        let mut t = third.clone();
        t.1.rows.pop();
        lost.push(t);
        let e = Merged::new(lost).unwrap_err().to_string();
        assert!(e.contains("is in no shard file"), "{e}");

        // a merge by a version whose grid differs
        let mut complete = files;
        complete.push(third);
        let mut replay = Points::replay(Merged::new(complete).unwrap());
        let e = study(&mut replay, 8).unwrap_err().to_string();
        assert!(
            e.contains("point 7 is search in the shards but sq/7 here"),
            "{e}"
        );
    }

    #[test]
    fn a_key_twice_is_a_bug_in_the_study() {
        let mut p = Points::all();
        p.run("a", || Ok(1)).unwrap();
        let e = p.run("a", || Ok(2)).unwrap_err().to_string();
        assert!(e.contains("used twice"), "{e}");
    }
}
