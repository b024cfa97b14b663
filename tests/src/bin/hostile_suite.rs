//! Runs the adversarial suite of issue 67 against the given binaries and prints a Markdown
//! table: per case the answer, the time to answer and the peak RSS of the coordinator and the
//! worker. With `--before`, the same cases run against an older build too, case by case,
//! each followed by the other build's run of it, so that both see the same machine.
//!
//! ```sh
//! cargo build --release -p tessera-coordinator -p tessera-worker -p tessera-tests
//! target/release/hostile-suite --bin-dir target/release [--before OLD/target/release] [--case NAME ...]
//! ```

use std::path::PathBuf;
use tessera_tests::hostile::{self, Bins, TABLE_HEADER};

fn bins(dir: &str) -> Bins {
    let dir = PathBuf::from(dir);
    Bins { tessera: dir.join("tessera"), worker: dir.join("tessera-worker") }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| args.windows(2).find(|w| w[0] == flag).map(|w| w[1].clone());
    let after = bins(&value("--bin-dir").unwrap_or_else(|| "target/release".into()));
    let before = value("--before").map(|d| bins(&d));
    let cases: Vec<String> = args.windows(2).filter(|w| w[0] == "--case").map(|w| w[1].clone()).collect();
    let scratch = tempfile::Builder::new().prefix("hostile-suite").tempdir().expect("scratch folder");
    let scratch = match std::env::var_os("TESSERA_SUITE_KEEP") {
        Some(_) => tempfile::TempDir::keep(scratch),
        None => scratch.path().to_path_buf(),
    };
    let header: Vec<&str> = TABLE_HEADER.lines().collect();
    println!("{} passed |\n{}---|", header[0], header[1]);
    let names: Vec<String> = hostile::cases()
        .iter()
        .filter(|c| cases.is_empty() || cases.iter().any(|f| c.name.contains(f.as_str())))
        .map(|c| c.name.to_string())
        .collect();
    let mut failed = 0;
    for name in names {
        for (label, b) in before.iter().map(|b| ("before", b)).chain([("after", &after)]) {
            for r in hostile::run(b, &scratch, std::slice::from_ref(&name)) {
                let ok = r.passed && r.survived();
                failed += (label == "after" && !ok) as usize;
                let row = r.row().replacen("| ", &format!("| {label}: "), 1);
                println!("{row} {} |", if ok { "yes" } else { "no" });
            }
        }
    }
    std::process::exit(if failed == 0 { 0 } else { 1 });
}
