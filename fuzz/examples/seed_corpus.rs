//! Writes the seed corpora (`crossroads_fuzz::seeds`) into
//! `<dir>/<target>/<name>` (default `corpus` beside this crate's manifest),
//! replacing the files of the same names. Run by `scripts/fuzz.sh seeds`.

use std::path::PathBuf;

fn main() -> std::io::Result<()> {
    let dir = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("corpus"));
    for (target, name, bytes) in crossroads_fuzz::seeds::all() {
        let folder = dir.join(target);
        std::fs::create_dir_all(&folder)?;
        std::fs::write(folder.join(name), bytes)?;
    }
    Ok(())
}
