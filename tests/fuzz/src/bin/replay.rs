//! Runs targets over files without AFL++: `replay TARGET PATH...` (a path may be a
//! folder: every file in it), or `replay --corpus DIR` for every target over
//! `DIR/<target>/`. Used by scripts/fuzz.sh to replay the committed corpus and the
//! crashes a run found; a panic aborts with the file named.

use std::path::{Path, PathBuf};

fn files(path: &Path) -> Vec<PathBuf> {
    if path.is_dir() {
        let mut v: Vec<PathBuf> = std::fs::read_dir(path)
            .map(|d| {
                d.flatten()
                    .map(|e| e.path())
                    .filter(|p| p.is_file())
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    } else {
        vec![path.to_path_buf()]
    }
}

fn run(target: &str, paths: &[PathBuf]) -> usize {
    let Some((_, f)) = dualgeo_fuzz::TARGETS.iter().find(|(n, _)| *n == target) else {
        eprintln!("replay: unknown target {target}");
        std::process::exit(2);
    };
    let mut n = 0;
    for file in paths.iter().flat_map(|p| files(p)) {
        let data = std::fs::read(&file).unwrap_or_else(|e| {
            eprintln!("replay: {}: {e}", file.display());
            std::process::exit(2);
        });
        eprintln!("replay: {target} {}", file.display());
        f(&data);
        n += 1;
    }
    n
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [flag, dir] if flag == "--corpus" => {
            for (target, _) in dualgeo_fuzz::TARGETS {
                let n = run(target, &[Path::new(dir).join(target)]);
                println!("{target}: {n} inputs, no panic");
            }
        }
        [target, paths @ ..] if !paths.is_empty() => {
            let paths: Vec<PathBuf> = paths.iter().map(PathBuf::from).collect();
            let n = run(target, &paths);
            println!("{target}: {n} inputs, no panic");
        }
        _ => {
            eprintln!("usage: replay TARGET PATH... | replay --corpus DIR");
            std::process::exit(2);
        }
    }
}
