//! `cargo xtask fuzz [--cases N] [--seed S]`: fuzzing of the scene parser and loader
//! (`flexmpc::scene::parse_str` / `load_str`, then one plant step) over arbitrary text,
//! token soup and mutations of the shipped scenes, each stage inside `catch_unwind`
//! (generator and classes: `flexmpc_verification::stress::scene_fuzz`). Counts classes and
//! panics (which must be 0), prints the time and writes `target/fuzz/report.md`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use flexmpc_verification::stress::scene_fuzz::{check, generate, Class, Source, MAX_ELEMENTS};

const USAGE: &str = "\
usage: cargo xtask fuzz [--cases N] [--seed S] [--show I]

  --cases N  number of inputs (default 100000)
  --seed S   stream seed (default 8, the seed of the reported runs); case i of a seed is
             always the same input, so a failure can be replayed alone
  --show I   print input I of the seed and how it ends (replay one case)

Each input goes through flexmpc::scene::parse_str, load_str (when the scene asks for at most
1000 elements in total: the loader itself has no cap) and one plant step, each inside
catch_unwind. Report: target/fuzz/report.md. The exit code is non-zero on any panic or silent
non-finite value.";

/// Entry point of the `fuzz` subcommand.
pub fn main(args: &[String]) -> Result<()> {
    let mut cases: u64 = 100_000;
    let mut seed: u64 = 8;
    let mut show: Option<u64> = None;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--cases" => {
                cases = it.next().context("--cases needs a number")?.parse().context("--cases")?
            }
            "--seed" => {
                seed = it.next().context("--seed needs a number")?.parse().context("--seed")?
            }
            "--show" => {
                show = Some(
                    it.next().context("--show needs a case index")?.parse().context("--show")?,
                )
            }
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            s => bail!("unknown argument `{s}`\n{USAGE}"),
        }
    }
    if let Some(i) = show {
        let (source, text) = generate(seed, i);
        println!("{text}");
        eprintln!("case {i} of seed {seed} ({}): {:?}", source_name(source), check(&text));
        return Ok(());
    }
    // Panics are caught and counted; keep the default hook from printing every one.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let start = Instant::now();
    let done = AtomicUsize::new(0);
    // Work shared by index over the available cores (std threads; results by case index).
    let next = AtomicUsize::new(0);
    let threads = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let mut results: Vec<(Source, Class, usize)> = Vec::with_capacity(cases as usize);
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed) as u64;
                        if i >= cases {
                            break;
                        }
                        let (source, text) = generate(seed, i);
                        let class = check(&text);
                        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                        if n % 10_000 == 0 {
                            eprintln!("fuzz: {n}/{cases} ({:.0} s)", start.elapsed().as_secs_f64());
                        }
                        mine.push((i, (source, class, text.len())));
                    }
                    mine
                })
            })
            .collect();
        let mut all: Vec<(u64, (Source, Class, usize))> =
            workers.into_iter().flat_map(|w| w.join().unwrap_or_default()).collect();
        all.sort_by_key(|x| x.0);
        results = all.into_iter().map(|x| x.1).collect();
    });
    std::panic::set_hook(hook);
    let seconds = start.elapsed().as_secs_f64();

    let mut by_class: BTreeMap<&'static str, usize> = BTreeMap::new();
    let mut by_source: BTreeMap<(&'static str, &'static str), usize> = BTreeMap::new();
    let mut defects = Vec::new();
    let mut overflows = Vec::new();
    for (i, (source, class, _)) in results.iter().enumerate() {
        *by_class.entry(class.label()).or_default() += 1;
        *by_source.entry((source_name(*source), class.label())).or_default() += 1;
        if class.is_defect() {
            defects.push(format!("case {i} ({}): {class:?}", source_name(*source)));
        }
        if let Class::Overflow(m) = class {
            overflows.push(format!("case {i}: {m}"));
        }
    }
    let panics = results.iter().filter(|r| matches!(r.1, Class::Panic(_))).count();
    let non_finite = results.iter().filter(|r| matches!(r.1, Class::NonFinite(_))).count();
    let bytes: usize = results.iter().map(|r| r.2).sum();

    let mut md = format!(
        "# Scene fuzzing\n\n`cargo xtask fuzz --cases {cases} --seed {seed}`: {cases} inputs \
         ({:.1} MB of text) in {seconds:.1} s wall time ({:.0} inputs/s).\n\n\
         **Panics: {panics}. Silent non-finite values: {non_finite}.**\n\n\
         | class | count |\n|---|---|\n",
        bytes as f64 / 1e6,
        cases as f64 / seconds.max(1e-9)
    );
    for (k, v) in &by_class {
        md.push_str(&format!("| {k} | {v} |\n"));
    }
    md.push_str("\n| source | class | count |\n|---|---|---|\n");
    for ((s, k), v) in &by_source {
        md.push_str(&format!("| {s} | {k} | {v} |\n"));
    }
    md.push_str(&format!(
        "\nSources: `bytes` random bytes (lossy UTF-8), `tokens` token soup of the scene \
         vocabulary and extreme values, `mutation` 1–4 mutations of a shipped scene. Cases whose \
         scene asks for more than {MAX_ELEMENTS} elements in total are not loaded \
         (`over the fuzz element cap`), to keep the fuzzer fast: a legal scene of up to \
         `flexmpc::scene::MAX_ELEMENTS_PER_BEAM` elements per beam is loaded and would be \
         stepped at its real cost (larger counts are a load error naming the field).\n"
    ));
    if !overflows.is_empty() {
        md.push_str(&format!(
            "\n## Loader finding: energy overflow from extreme finite values ({} cases)\n\n\
             `load_str` accepts any finite `gravity`, `initial.rigid.omega` and `center`; \
             magnitudes near 1e308 make the kinetic or gravity energy overflow to ±inf (the \
             state and positions stay finite). Replay with `cargo xtask fuzz --seed {seed} \
             --show I`.\n\n",
            overflows.len()
        ));
        for o in overflows.iter().take(20) {
            md.push_str(&format!("- {o}\n"));
        }
    }
    if !defects.is_empty() {
        md.push_str("\n## Defects\n\n");
        for d in defects.iter().take(50) {
            md.push_str(&format!("- {}\n", d.replace('\n', " ")));
        }
    }
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/fuzz");
    std::fs::create_dir_all(&dir)?;
    std::fs::write(dir.join("report.md"), &md)?;
    println!("{md}");
    println!("report: {}", dir.join("report.md").display());
    if panics + non_finite > 0 {
        bail!("{panics} panic(s) and {non_finite} silent non-finite value(s)");
    }
    Ok(())
}

fn source_name(s: Source) -> &'static str {
    match s {
        Source::Bytes => "bytes",
        Source::Tokens => "tokens",
        Source::Mutation => "mutation",
    }
}
