//! `cargo run --release --example analyze -- MODEL.json [name=value …]`: the core
//! alone, for quick experiments without the server crate.
fn main() {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .expect("usage: analyze MODEL.json [name=value …]");
    let text = std::fs::read_to_string(&path).expect("readable model file");
    let model = kea_core::model_from_json(&text).unwrap_or_else(|e| panic!("{e}"));
    let set = args
        .map(|a| {
            let (k, v) = a.split_once('=').expect("name=value");
            (k.to_string(), v.parse::<f64>().expect("a number"))
        })
        .collect();
    let t = std::time::Instant::now();
    match kea_core::analyze(&model, &set, &mut kea_core::NoProgress) {
        Ok(mut r) => {
            r.timing.wall_ms = t.elapsed().as_secs_f64() * 1e3;
            print!("{}", kea_core::analysis::report::criteria_table(&r));
        }
        Err(e) => eprintln!("{e}"),
    }
}
