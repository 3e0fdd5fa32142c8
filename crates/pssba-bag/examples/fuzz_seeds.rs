//! Writes the seed corpora of the fuzz targets (crates/pssba-bag/fuzz) from the bag fixtures:
//! every message of the small bags, prefixed with the `messages` target's selector byte, and
//! the small recording files themselves for the `files` target.
//!
//! `cargo run -p pssba-bag --example fuzz_seeds -- tests/fixtures/bags crates/pssba-bag/fuzz/corpus`

use std::path::PathBuf;

use pssba_bag::Bag;
use pssba_bag::msg::{Kind, Wire};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [fixtures, corpus] = &args[..] else {
        return Err("usage: fuzz_seeds FIXTURES_DIR CORPUS_DIR".into());
    };
    let messages_dir = corpus.join("messages");
    let files_dir = corpus.join("files");
    std::fs::create_dir_all(&messages_dir)?;
    std::fs::create_dir_all(&files_dir)?;
    let small = fixtures.join("small");
    let mut written = 0;
    let mut paths: Vec<(PathBuf, bool)> = std::fs::read_dir(&small)?
        .map(|e| Ok((e?.path(), true)))
        .collect::<Result<_, std::io::Error>>()?;
    // The big fixtures give the first message of each topic only (Livox and CDR odometry).
    for big in ["ros1_bz2_livox.bag", "ros2_sqlite3", "ros1_lz4.bag"] {
        paths.push((fixtures.join(big), false));
    }
    paths.sort();
    for (path, whole) in paths {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_string();
        if whole {
            std::fs::copy(&path, files_dir.join(&name))?;
        }
        let Ok(bag) = Bag::open(&path) else { continue };
        let topics: Vec<String> = bag.topics().iter().map(|t| t.name.clone()).collect();
        for message in bag.messages(&topics)? {
            let message = message?;
            if !whole && message.index > 0 {
                continue;
            }
            let Some(topic) = bag.topic(&message.message.topic) else {
                continue;
            };
            let decoder = match Kind::of(&topic.type_name) {
                Some(Kind::PointCloud2) => 0u8,
                Some(Kind::LivoxCustom) => 1,
                Some(Kind::Odometry) => 2,
                Some(Kind::PoseStamped | Kind::PoseWithCovarianceStamped) => 3,
                Some(Kind::Tf) => 4,
                None => continue,
            };
            let wire = u8::from(topic.wire == Wire::Cdr);
            let mut seed = vec![decoder << 1 | wire];
            seed.extend(&message.message.data);
            let seed_name = format!(
                "{name}-{}-{}",
                topic.name.trim_start_matches('/').replace('/', "_"),
                message.index
            );
            std::fs::write(messages_dir.join(seed_name), seed)?;
            written += 1;
        }
    }
    println!("{written} message seeds in {}", messages_dir.display());
    Ok(())
}
