//! Model, PID and W_m JSON files as `ferrosid codegen` reads them, then the generator itself.
#![no_main]
use ferrosid::cli::codegen::{read_model_file, read_pid, read_weight};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let p = ferrosid_fuzz::scratch_file("json", data);
    if let Ok((sys, _op)) = read_model_file(&p) {
        if sys.is_discrete() && sys.n_states() <= 64 {
            let _ = sys.poles();
            let _ = sys.d2c_zoh();
        }
    }
    let _ = read_pid(&p, 1e-3, None);
    let _ = read_pid(&p, 1e-3, Some(10.0));
    let _ = read_weight(&p);
});
