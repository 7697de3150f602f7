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

/// 5 since keyframes carry their camera's mount: a store of kind 3 (before it) is
/// refused and matching starts fresh.
pub const KEYFRAME_KIND: u32 = 5;
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

    /// After an admission (`admitted[uav]`): writes every keyframe of the rings not on
    /// disk yet, then the new index, then removes the files of evicted keyframes.
    /// Every keyframe, not only each ring's newest: a refresh's admission lands between
    /// pairs, so a ring can gain two keyframes between saves; writing only the newest
    /// left the index naming a file that was never written, and the next incarnation
    /// refused the store and rebuilt its rings (2.6 s without estimates in
    /// `e2e_chaos`).
    pub fn save(
        &mut self,
        chain: &VisionChain,
        admitted: [bool; 2],
    ) -> Result<(), CheckpointError> {
        if !admitted.iter().any(|a| *a) {
            return Ok(());
        }
        let index = chain.ring_index();
        let named: BTreeSet<(usize, u64)> = (0..2)
            .flat_map(|u| index.keyframes[u].iter().map(move |s| (u, *s)))
            .collect();
        let missing: Vec<(usize, u64)> = named.difference(&self.on_disk).copied().collect();
        for (u, seq) in missing {
            let uav = [Uav::Left, Uav::Right][u];
            if let Some(kf) = chain.keyframe_snapshot(uav, seq) {
                checkpoint::write(&self.keyframe_path(u, seq), KEYFRAME_KIND, &kf)?;
                self.on_disk.insert((u, seq));
            }
        }
        checkpoint::write(&self.index_path(), INDEX_KIND, &index)?;
        let evicted: Vec<(usize, u64)> = self.on_disk.difference(&named).copied().collect();
        for (u, s) in evicted {
            let _ = std::fs::remove_file(self.keyframe_path(u, s));
            self.on_disk.remove(&(u, s));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ring_snapshot::tests::snapshot;
    use crate::ring_snapshot::RingIndex;

    fn chain_with(keyframes: &[u64]) -> VisionChain {
        let config = crate::MatchingConfig::default();
        let mut chain = VisionChain::new(config, geolocation::EstimatorConfig::default()).unwrap();
        let index = RingIndex {
            keyframes: [vec![], keyframes.to_vec()],
            smoothed: [None, None],
            segment: 0,
        };
        chain
            .restore_rings(&index, |_, seq| Ok(snapshot(seq)))
            .unwrap();
        chain
    }

    /// Two keyframes admitted between saves (a refresh's admission landing, then the
    /// pair's own): both are written, and the next incarnation restores both.
    #[test]
    fn every_keyframe_the_index_names_is_written() {
        let dir = std::env::temp_dir().join(format!("dualgeo-ring-store-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut store = RingStore::open(&dir).unwrap();
        store.save(&chain_with(&[3]), [false, true]).unwrap();
        store.save(&chain_with(&[3, 5, 9]), [false, true]).unwrap();
        for seq in [3, 5, 9] {
            assert!(
                dir.join(format!("matching/kf-1-{seq}.ckpt")).is_file(),
                "{seq}"
            );
        }
        let mut next = chain_with(&[]);
        let restored = RingStore::open(&dir).unwrap().restore(&mut next);
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(restored, Ok(3));
        assert_eq!(next.ring_index().keyframes[1], vec![3, 5, 9]);
    }
}
