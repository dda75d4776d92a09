//! `pgrf search`: the paper's sampling search (Algorithm 2). Its flags
//! become a `SearchRequest`; `pgrf_app::search::run` makes validation
//! pairs like the model's training pairs, scores the two-stage sampler at
//! t = s, 2s, .., 1, draws PSNR against t and writes the best t into the
//! weight file (atomically); this prints the table or JSON.

use crate::progress::Bar;
use anyhow::Result;
use pgrf_app::search;

pub use pgrf_app::search::flags::SearchArgs;

pub fn run(a: &SearchArgs, g: &crate::Globals) -> Result<()> {
    let kernels = g.kernels;
    let mut req = a.request(kernels);
    req.darktable = g.darktable.map(Into::into);
    let bar = Bar::new("search", 0, "network evaluations", a.json);
    let warn = |w: &str| {
        if !a.json {
            eprintln!("note: --val: {w}");
        }
    };
    let found = search::run(&req, &bar, &warn)?;
    if a.json {
        println!("{}", found.json(&req));
    } else {
        print!("{}", found.table(&req));
    }
    Ok(())
}
