//! The HTML report renders in headless Chromium with every figure loaded: a short closed loop
//! of the shipped 2D NMPC scene (8 elements per link, 1 s) writes its report under the target
//! directory; Chromium takes a screenshot (`target/report-screenshot.png`) and dumps the DOM
//! after the page's own script has marked each `<img>` as loaded (`naturalWidth > 0`) or not.
//!
//! Chromium is required: Debian's `chromium` package (`.ci/run` installs it when missing).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";

fn target_dir() -> PathBuf {
    // CARGO_TARGET_TMPDIR is <target>/tmp
    Path::new(env!("CARGO_TARGET_TMPDIR")).parent().expect("target dir").to_path_buf()
}

/// Runs Chromium headless on `url` with `extra` flags; returns stdout. Fails after 120 s.
fn chromium(url: &str, extra: &[String]) -> String {
    let profile = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "chromium-profile-{}-{}",
        std::process::id(),
        extra.len()
    ));
    let _ = std::fs::remove_dir_all(&profile);
    std::fs::create_dir_all(&profile).unwrap();
    let mut child = Command::new(CHROMIUM)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {CHROMIUM}: {e}"));
    let stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut { stdout }, &mut s).unwrap();
        s
    });
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "chromium exited with {status}");
            break;
        }
        // a guard against a hung browser, not a judgement of speed
        if start.elapsed() > Duration::from_secs(900) {
            let _ = child.kill();
            panic!("chromium did not finish within 900 s (hung?)");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let _ = std::fs::remove_dir_all(&profile);
    reader.join().unwrap()
}

#[test]
fn report_renders_in_chromium_with_every_figure() {
    assert!(
        Path::new(CHROMIUM).exists(),
        "{CHROMIUM} is missing: this test needs headless Chromium; install it with \
         `apt-get update && apt-get install -y chromium` (Debian; .ci/run does this)"
    );
    // a short run of the shipped scene on a coarse mesh
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = std::fs::read_to_string(root.join("scenes/paper-2d-mpc.toml")).unwrap();
    let work = target_dir().join("report-test");
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).unwrap();
    let scene = work.join("paper-2d-mpc-small.toml");
    std::fs::write(&scene, text.replace("elements = 50", "elements = 8")).unwrap();
    let out = work.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
        .args(["--quiet", "mpc"])
        .arg(&scene)
        .args(["--duration", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let index = out.join("index.html").canonicalize().unwrap();
    let html = std::fs::read_to_string(&index).unwrap();
    // offline: no external resources
    for bad in ["src=\"http", "href=\"http", "src='http", "@import", "url(http"] {
        assert!(!html.contains(bad), "index.html refers to an external resource ({bad})");
    }
    let n_img = html.matches("<img ").count();
    assert!(n_img >= 8, "expected the cost, inputs, angles, solve-time, snapshot, animation and two mode figures, found {n_img} <img>");
    let url = format!("file://{}", index.display());

    let shot = target_dir().join("report-screenshot.png");
    let _ = std::fs::remove_file(&shot);
    chromium(
        &url,
        &[format!("--screenshot={}", shot.display()), "--window-size=1280,2000".to_string()],
    );
    let png = std::fs::read(&shot).expect("the screenshot was written");
    assert!(png.starts_with(b"\x89PNG") && png.len() > 20_000, "screenshot: {} bytes", png.len());

    let dom =
        chromium(&url, &["--dump-dom".to_string(), "--virtual-time-budget=10000".to_string()]);
    // the page's script ran and counted the figures
    let status = dom
        .split("id=\"figure-status\"")
        .nth(1)
        .expect("the DOM has the figure status line")
        .split('>')
        .next()
        .unwrap()
        .to_string();
    let attr = |name: &str| -> usize {
        status
            .split(&format!("{name}=\""))
            .nth(1)
            .and_then(|r| r.split('"').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| {
                panic!("no {name} in the status element `{status}`: the script did not run")
            })
    };
    assert_eq!(attr("data-total"), n_img, "{status}");
    assert_eq!(attr("data-loaded"), n_img, "some figures did not load: {status}");
    let marked_yes = dom.matches("data-loaded=\"yes\"").count();
    let marked_no = dom.matches("data-loaded=\"no\"").count();
    assert_eq!((marked_yes, marked_no), (n_img, 0), "per-image marks");
}
