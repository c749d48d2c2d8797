//! What several of the train crate's integration tests share.

use std::path::Path;

use train::RunDir;

/// The shipped Person-MinkUNet run's config and checkpoints (the facing stage beside them
/// included), copied to `dir`, so a test may write into it.
pub fn shipped_copy(dir: &Path) -> RunDir {
    fn copy_tree(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                copy_tree(&e.path(), &to.join(e.file_name()));
            } else {
                std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
            }
        }
    }
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../weights/person_minkunet");
    copy_tree(&src.join("checkpoints"), &dir.join("checkpoints"));
    std::fs::copy(src.join("config.toml"), dir.join("config.toml")).unwrap();
    RunDir::at(dir)
}
