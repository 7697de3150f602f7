//! Rendering a simulator step into the chain's inputs, shared by the tests that run
//! the chain on rendered frames. Truth (the true poses) is given only when a test asks
//! for the Table 1 protocol.

use acquisition::sim::{SimStep, Simulator};
use detection::{ColourBlobDetector, Detector};
use matching::FrameInput;
use opencv::core as cv;
use opencv::prelude::*;
use shared_types::lens::Distortion;

/// Two black BGR frames of the simulator's camera size.
pub fn blank_pair(sim: &Simulator) -> [cv::Mat; 2] {
    let (w, h) = (
        sim.config().camera.width as i32,
        sim.config().camera.height as i32,
    );
    let blank =
        || cv::Mat::new_rows_cols_with_default(h, w, cv::CV_8UC3, cv::Scalar::all(0.0)).unwrap();
    [blank(), blank()]
}

/// Renders `step` into `images` and returns both frames as the chain takes them: the
/// detector's centres, the measured poses (or the true ones with `true_poses`), and
/// `lens` as the camera's distortion.
pub fn inputs<'a>(
    sim: &mut Simulator,
    step: &SimStep,
    images: &'a mut [cv::Mat; 2],
    detector: &mut ColourBlobDetector,
    true_poses: bool,
    lens: Distortion,
) -> Vec<FrameInput<'a>> {
    let w = images[0].cols();
    {
        let [l, r] = &mut *images;
        sim.render_pair(
            step,
            l.data_bytes_mut().unwrap(),
            r.data_bytes_mut().unwrap(),
            3 * w as usize,
        );
    }
    let images: &'a [cv::Mat; 2] = images;
    step.frames
        .iter()
        .zip(images)
        .map(|(frame, image)| FrameInput {
            seq: frame.seq,
            t_s: frame.t_s,
            pose: if true_poses {
                frame.true_pose
            } else {
                frame.measured
            },
            image,
            detection: detector.detect(image).unwrap().map(|d| d.centre),
            intrinsics: sim.intrinsics(),
            distortion: lens,
            width: image.cols() as u32,
            height: image.rows() as u32,
        })
        .collect()
}
