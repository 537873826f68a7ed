//! Tables of the bench studies and their markdown, CSV and JSON forms.

use super::plot::Chart;
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

/// One cell.
#[derive(Clone, Debug)]
pub(crate) enum V {
    /// A number (NaN / ∞ allowed: shown as `—` / `inf`, JSON `null`).
    N(f64),
    /// Text.
    S(String),
}

impl From<f64> for V {
    fn from(x: f64) -> Self {
        V::N(x)
    }
}

impl From<usize> for V {
    fn from(x: usize) -> Self {
        V::N(x as f64)
    }
}

impl From<&str> for V {
    fn from(s: &str) -> Self {
        V::S(s.to_string())
    }
}

impl From<String> for V {
    fn from(s: String) -> Self {
        V::S(s)
    }
}

/// How a numeric column is shown in markdown (CSV and JSON keep full precision).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Fmt {
    /// Integer.
    Int,
    /// Three significant digits, exponent form.
    Sci,
    /// Fixed number of decimals.
    Fix(usize),
    /// A text column (numbers shown as they are).
    Text,
}

/// A table: a key (file suffix), a title, typed columns and rows.
#[derive(Clone, Debug)]
pub(crate) struct Table {
    /// File suffix (`<study>-<key>.csv`).
    pub key: &'static str,
    /// Heading.
    pub title: String,
    /// Column names and formats.
    pub columns: Vec<(String, Fmt)>,
    /// Rows, one value per column.
    pub rows: Vec<Vec<V>>,
}

impl Table {
    /// An empty table.
    pub fn new(key: &'static str, title: impl Into<String>, columns: &[(&str, Fmt)]) -> Self {
        Self {
            key,
            title: title.into(),
            columns: columns.iter().map(|(n, f)| (n.to_string(), *f)).collect(),
            rows: Vec::new(),
        }
    }

    /// Appends a row (must have one value per column).
    pub fn push(&mut self, row: Vec<V>) {
        debug_assert_eq!(row.len(), self.columns.len(), "row width of table {}", self.key);
        self.rows.push(row);
    }

    fn cell_md(v: &V, f: Fmt) -> String {
        match v {
            V::S(s) => s.clone(),
            V::N(x) if x.is_nan() => "—".into(),
            V::N(x) if x.is_infinite() => "inf".into(),
            V::N(x) => match f {
                Fmt::Int => format!("{}", x.round() as i64),
                Fmt::Sci => format!("{x:.2e}"),
                Fmt::Fix(d) => format!("{x:.d$}"),
                Fmt::Text => format!("{x}"),
            },
        }
    }

    /// Markdown table.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let names: Vec<&str> = self.columns.iter().map(|c| c.0.as_str()).collect();
        let _ = writeln!(s, "| {} |", names.join(" | "));
        let aligns: Vec<&str> = self
            .columns
            .iter()
            .enumerate()
            .map(
                |(i, _)| {
                    if self.rows.iter().all(|r| matches!(r[i], V::N(_))) {
                        "---:"
                    } else {
                        "---"
                    }
                },
            )
            .collect();
        let _ = writeln!(s, "|{}|", aligns.join("|"));
        for r in &self.rows {
            let cells: Vec<String> =
                r.iter().zip(&self.columns).map(|(v, c)| Self::cell_md(v, c.1)).collect();
            let _ = writeln!(s, "| {} |", cells.join(" | "));
        }
        s
    }

    /// CSV with full precision (empty field for NaN).
    pub fn csv(&self) -> String {
        let quote = |s: &str| {
            if s.contains([',', '"', '\n']) {
                format!("\"{}\"", s.replace('"', "\"\""))
            } else {
                s.to_string()
            }
        };
        let mut s = String::new();
        let names: Vec<String> = self.columns.iter().map(|c| quote(&c.0)).collect();
        let _ = writeln!(s, "{}", names.join(","));
        for r in &self.rows {
            let cells: Vec<String> = r
                .iter()
                .map(|v| match v {
                    V::S(t) => quote(t),
                    V::N(x) if x.is_nan() => String::new(),
                    V::N(x) => format!("{x:e}"),
                })
                .collect();
            let _ = writeln!(s, "{}", cells.join(","));
        }
        s
    }

    /// JSON: `{key, title, rows: [{column: value}]}` (non-finite numbers as `null`).
    pub fn json(&self) -> serde_json::Value {
        let rows: Vec<serde_json::Value> = self
            .rows
            .iter()
            .map(|r| {
                let mut o = serde_json::Map::new();
                for (v, c) in r.iter().zip(&self.columns) {
                    let j = match v {
                        V::S(t) => serde_json::json!(t),
                        V::N(x) if x.is_finite() => serde_json::json!(x),
                        V::N(_) => serde_json::Value::Null,
                    };
                    o.insert(c.0.clone(), j);
                }
                serde_json::Value::Object(o)
            })
            .collect();
        serde_json::json!({ "key": self.key, "title": self.title, "rows": rows })
    }
}

/// Where and how a study ran.
#[derive(Clone, Debug, Default)]
pub(crate) struct Header {
    /// The exact command.
    pub command: String,
    /// CPU model and count.
    pub machine: String,
    /// Load average (1, 5, 15 min) when the study started.
    pub load_start: String,
    /// Load average when it ended.
    pub load_end: String,
    /// Wall time of the study (s).
    pub wall_s: f64,
    /// Process CPU time over wall time during the study (1 = one core fully ours).
    pub cpu_over_wall: f64,
    /// `--quick` subset.
    pub quick: bool,
}

/// The outcome of one study.
pub(crate) struct Study {
    /// File stem, e.g. `a-mesh`.
    pub id: &'static str,
    /// Heading, e.g. `(a) FE mesh against frequency error and time`.
    pub title: String,
    /// What was run (one paragraph).
    pub setup: String,
    /// Tables.
    pub tables: Vec<Table>,
    /// Plots.
    pub charts: Vec<Chart>,
    /// Findings computed from the data (figures).
    pub notes: Vec<String>,
    /// Filled in by the driver.
    pub header: Header,
}

impl Study {
    /// A study with no tables yet.
    pub fn new(id: &'static str, title: impl Into<String>, setup: impl Into<String>) -> Self {
        Self {
            id,
            title: title.into(),
            setup: setup.into(),
            tables: Vec::new(),
            charts: Vec::new(),
            notes: Vec::new(),
            header: Header::default(),
        }
    }

    fn header_md(&self) -> String {
        let h = &self.header;
        format!(
            "`{}` ({} tier) · machine: {} · load average (1/5/15 min) {} at start, {} at end · \
             study wall time {:.1} s, process CPU/wall {:.2} · one thread (rayon pool of 1), \
             times are medians of repeated runs (`Instant`)",
            h.command,
            if h.quick { "quick" } else { "full" },
            h.machine,
            h.load_start,
            h.load_end,
            h.wall_s,
            h.cpu_over_wall
        )
    }

    /// The study as markdown (tables, notes, links to the plots by file name).
    pub fn markdown(&self) -> String {
        let mut s = format!("## {}\n\n{}\n\n{}\n\n", self.title, self.header_md(), self.setup);
        for c in &self.charts {
            let _ = writeln!(s, "![{}]({}-{}.svg)\n", c.title, self.id, c.key);
        }
        for t in &self.tables {
            let _ = writeln!(s, "### {}\n\n{}", t.title, t.markdown());
        }
        if !self.notes.is_empty() {
            let _ = writeln!(s, "Findings:\n");
            for n in &self.notes {
                let _ = writeln!(s, "* {n}");
            }
            s.push('\n');
        }
        s
    }

    /// Writes `<id>.md`, `<id>.json`, `<id>-<table>.csv` and `<id>-<chart>.svg` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let w = |name: String, text: &str| {
            let p = dir.join(&name);
            std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))
        };
        w(format!("{}.md", self.id), &self.markdown())?;
        for t in &self.tables {
            w(format!("{}-{}.csv", self.id, t.key), &t.csv())?;
        }
        let h = &self.header;
        let json = serde_json::json!({
            "study": self.id,
            "title": self.title,
            "setup": self.setup,
            "command": h.command,
            "machine": h.machine,
            "load_average_start": h.load_start,
            "load_average_end": h.load_end,
            "wall_s": h.wall_s,
            "cpu_over_wall": h.cpu_over_wall,
            "quick": h.quick,
            "tables": self.tables.iter().map(Table::json).collect::<Vec<_>>(),
            "notes": self.notes,
        });
        w(format!("{}.json", self.id), &serde_json::to_string_pretty(&json)?)?;
        for c in &self.charts {
            let p = dir.join(format!("{}-{}.svg", self.id, c.key));
            c.draw(&p).with_context(|| format!("plotting {}", p.display()))?;
        }
        Ok(())
    }

    /// Copies the markdown and the SVG plots from `from` to `to`.
    pub fn publish(&self, from: &Path, to: &Path) -> Result<()> {
        let mut names = vec![format!("{}.md", self.id)];
        names.extend(self.charts.iter().map(|c| format!("{}-{}.svg", self.id, c.key)));
        for n in names {
            std::fs::copy(from.join(&n), to.join(&n))
                .with_context(|| format!("copying {n} to {}", to.display()))?;
        }
        Ok(())
    }
}

/// All studies in one markdown document.
pub(crate) fn summary(studies: &[Study]) -> String {
    let mut s = String::from("# flexmpc run time against error (`cargo xtask bench`)\n\n");
    for st in studies {
        s.push_str(&st.markdown());
    }
    s
}
