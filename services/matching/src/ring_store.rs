//! Where matching keeps its keyframe rings between incarnations (issue #13):
//! `<state-dir>/matching/kf-<uav>-<seq>.ckpt` per keyframe and `index.ckpt` naming the
//! ones in the rings, each written atomically (`shared_types::checkpoint`). A keyframe
//! file is written when the keyframe is admitted, before the index that names it; an
//! evicted keyframe's file is removed after the index that no longer names it. A
//! reader therefore never finds the index naming a file that is not there.

use crate::chain::VisionChain;
use crate::ring_snapshot::{KeyframeSnapshot, RingIndex};
use shared_types::checkpoint::{self, CheckpointError};
use shared_types::conventions::Uav;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

pub const KEYFRAME_KIND: u32 = 3;
pub const INDEX_KIND: u32 = 4;

pub struct RingStore {
    dir: PathBuf,
    /// Keyframe files written and not yet removed.
    on_disk: BTreeSet<(usize, u64)>,
}

impl RingStore {
    /// The store in `<state_dir>/matching` (created owner-only).
    pub fn open(state_dir: &Path) -> Result<Self, CheckpointError> {
        let dir = state_dir.join("matching");
        checkpoint::create_dir(&dir)?;
        Ok(Self {
            dir,
            on_disk: BTreeSet::new(),
        })
    }

    fn keyframe_path(&self, uav: usize, seq: u64) -> PathBuf {
        self.dir.join(format!("kf-{uav}-{seq}.ckpt"))
    }

    fn index_path(&self) -> PathBuf {
        self.dir.join("index.ckpt")
    }

    /// Refills `chain`'s rings from the store. Returns the keyframes restored (0 on a
    /// first start); an error means the store cannot be trusted (the caller starts
    /// fresh, and the next admission overwrites it). Files no index names are removed.
    pub fn restore(&mut self, chain: &mut VisionChain) -> Result<usize, String> {
        let index: Option<RingIndex> =
            checkpoint::read(&self.index_path(), INDEX_KIND).map_err(|e| e.to_string())?;
        let restored = match &index {
            None => 0,
            Some(index) => chain.restore_rings(index, |uav, seq| {
                checkpoint::read::<KeyframeSnapshot>(
                    &self.keyframe_path(uav.index(), seq),
                    KEYFRAME_KIND,
                )
                .map_err(|e| e.to_string())?
                .ok_or_else(|| format!("keyframe {seq} of {uav:?} is missing"))
            })?,
        };
        let named: BTreeSet<(usize, u64)> = index
            .iter()
            .flat_map(|i| (0..2).flat_map(move |u| i.keyframes[u].iter().map(move |s| (u, *s))))
            .collect();
        if let Ok(entries) = std::fs::read_dir(&self.dir) {
            for path in entries.flatten().map(|e| e.path()) {
                let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
                let keep = name == "index.ckpt"
                    || named
                        .iter()
                        .any(|&(u, s)| name == format!("kf-{u}-{s}.ckpt"));
                if !keep {
                    let _ = std::fs::remove_file(&path);
                }
            }
        }
        self.on_disk = named;
        Ok(restored)
    }

    /// Saves the keyframes just admitted (`admitted[uav]`) and the new index, then
    /// removes the files of evicted keyframes.
    pub fn save(
        &mut self,
        chain: &VisionChain,
        admitted: [bool; 2],
    ) -> Result<(), CheckpointError> {
        if !admitted.iter().any(|a| *a) {
            return Ok(());
        }
        for uav in [Uav::Left, Uav::Right] {
            if !admitted[uav.index()] {
                continue;
            }
            if let Some(kf) = chain.newest_keyframe(uav) {
                checkpoint::write(&self.keyframe_path(uav.index(), kf.seq), KEYFRAME_KIND, &kf)?;
                self.on_disk.insert((uav.index(), kf.seq));
            }
        }
        let index = chain.ring_index();
        checkpoint::write(&self.index_path(), INDEX_KIND, &index)?;
        let named: BTreeSet<(usize, u64)> = (0..2)
            .flat_map(|u| index.keyframes[u].iter().map(move |s| (u, *s)))
            .collect();
        let evicted: Vec<(usize, u64)> = self.on_disk.difference(&named).copied().collect();
        for (u, s) in evicted {
            let _ = std::fs::remove_file(self.keyframe_path(u, s));
            self.on_disk.remove(&(u, s));
        }
        Ok(())
    }
}
