//! Every config the repository ships resolves: the run configs in `experiments/`, every variant and
//! seed of every sweep in `experiments/sweeps/` and `experiments/history/`, and the shipped
//! weights' `config.toml`. A typo in
//! a key (the configs deny unknown fields) or a value `validate` rejects fails here, not an hour
//! into someone's run.

use std::path::{Path, PathBuf};

use train::config::RunConfig;
use train::run_dir::RunDir;
use train::sweep::SweepConfig;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tomls(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    files
}

#[test]
fn every_run_config_resolves() {
    let files = tomls(&workspace().join("experiments"));
    assert!(files.iter().any(|p| p.ends_with("quickstart.toml")), "the quickstart config is among {files:?}");
    for path in &files {
        RunConfig::load(path, &[]).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
    }
}

#[test]
fn every_sweep_resolves_every_variant_and_seed() {
    let mut files = tomls(&workspace().join("experiments/sweeps"));
    files.extend(tomls(&workspace().join("experiments/history")));
    assert!(files.len() >= 19, "sweeps found: {files:?}");
    for path in &files {
        let (sweep, base) = SweepConfig::load(path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        let jobs = sweep.jobs(&base).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        assert!(!jobs.is_empty(), "{}: no runs", path.display());
    }
}

#[test]
fn the_shipped_weights_configs_resolve() {
    let weights = workspace().join("weights");
    let mut found = 0;
    for entry in std::fs::read_dir(&weights).unwrap() {
        let run = RunDir::at(entry.unwrap().path());
        if run.config_file().is_file() {
            // As `infer --run` reads it.
            run.config().unwrap_or_else(|e| panic!("{}: {e:#}", run.root.display()));
            found += 1;
        }
    }
    assert!(found >= 2, "Person-MinkUNet's and CenterPoint's weights ship with their configs");
}

/// Every key a resolved config holds (tables and leaves, by name), over every shipped run config.
fn config_keys() -> std::collections::BTreeSet<String> {
    fn walk(v: &toml::Value, keys: &mut std::collections::BTreeSet<String>) {
        match v {
            toml::Value::Table(t) => {
                for (k, v) in t {
                    keys.insert(k.clone());
                    walk(v, keys);
                }
            }
            toml::Value::Array(a) => a.iter().for_each(|v| walk(v, keys)),
            _ => {}
        }
    }
    let mut keys = std::collections::BTreeSet::new();
    for path in tomls(&workspace().join("experiments")) {
        let cfg = RunConfig::load(&path, &[]).unwrap();
        walk(&toml::from_str(&cfg.to_toml().unwrap()).unwrap(), &mut keys);
    }
    keys
}

#[test]
fn experiments_readme_documents_every_config_key_and_sweep_file() {
    let readme = std::fs::read_to_string(workspace().join("experiments/README.md")).unwrap();
    let missing: Vec<String> = config_keys().into_iter().filter(|k| !readme.contains(&format!("`{k}`")) && !readme.contains(&format!("`{k} ")) && !readme.contains(&format!("[{k}]")) && !readme.contains(&format!(".{k}]"))).collect();
    assert!(missing.is_empty(), "keys not documented in experiments/README.md: {missing:?}");
    let sweeps: Vec<String> = ["sweeps", "history"]
        .iter()
        .flat_map(|dir| tomls(&workspace().join("experiments").join(dir)).into_iter().map(move |p| format!("{dir}/{}", p.file_name().unwrap().to_string_lossy())))
        .filter(|name| !readme.contains(&format!("`{name}`")))
        .collect();
    assert!(sweeps.is_empty(), "sweep files not listed in experiments/README.md: {sweeps:?}");
}
