//! The CLI's one progress display: an indicatif bar (rate, ETA) behind the
//! libraries' `pgrf_core::Progress` trait, with one style for every command.

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use pgrf_core::Progress;

/// A progress bar on stderr, hidden with `--quiet` (and by indicatif itself
/// when stderr is not a terminal); `--quiet` also silences its notes.
pub struct Bar {
    bar: ProgressBar,
    quiet: bool,
    /// The display it is one of ([`Bar::within`]), left when it is dropped.
    multi: Option<MultiProgress>,
}

/// The one bar style: what runs, how far, how fast, how long to go.
fn style(units: &str) -> ProgressStyle {
    ProgressStyle::with_template(&format!(
        "{{spinner}} {{prefix}} [{{bar:30}}] {{pos}}/{{len}} {units}  {{per_sec}}  eta {{eta}}  {{msg}}"
    ))
    .expect("valid template")
    .progress_chars("=> ")
}

impl Bar {
    /// A bar named `prefix` counting `len` `units`.
    pub fn new(prefix: impl Into<String>, len: u64, units: &str, quiet: bool) -> Bar {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(len)
        };
        bar.set_style(style(units));
        bar.set_prefix(prefix.into());
        Bar {
            bar,
            quiet,
            multi: None,
        }
    }

    /// [`Bar::new`] drawn as one of `multi`'s bars (a batch's bar over
    /// files above each file's bar over tiles), and taken off it when
    /// dropped, so a batch of any length holds one file's bar at a time.
    pub fn within(
        multi: &MultiProgress,
        prefix: impl Into<String>,
        len: u64,
        units: &str,
        quiet: bool,
    ) -> Bar {
        let mut b = Bar::new(prefix, len, units, quiet);
        if !quiet {
            b.bar = multi.add(b.bar.clone());
            b.multi = Some(multi.clone());
        }
        b
    }

    /// The underlying bar, for messages and ticking.
    pub fn bar(&self) -> &ProgressBar {
        &self.bar
    }

    /// Print `line` above the bar (plainly when the bar is hidden; not at
    /// all with `--quiet`).
    pub fn println(&self, line: &str) {
        if self.quiet {
            return;
        }
        if self.bar.is_hidden() {
            eprintln!("{line}");
        } else {
            self.bar.println(line);
        }
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        if let Some(m) = &self.multi {
            m.remove(&self.bar);
        }
    }
}

impl Progress for Bar {
    fn start(&self, len: u64, what: &str) {
        self.bar.set_style(style(what));
        self.bar.set_length(len);
        self.bar.set_position(0);
    }
    fn advance(&self, n: u64) {
        self.bar.inc(n);
    }
    fn set_position(&self, done: u64) {
        // A jump (a resumed run) must not count as speed.
        let jump = done > self.bar.position() + 1;
        self.bar.set_position(done);
        if jump {
            self.bar.reset_eta();
        }
    }
    fn message(&self, msg: &str) {
        self.bar.set_message(msg.to_string());
    }
    fn note(&self, line: &str) {
        self.println(line);
    }
    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
