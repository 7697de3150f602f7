//! `dualgeo simulate`: render a scenario preset into a recording (format v1), or into a
//! flight (videos + MAVLink logs, `--flight-out`).

use acquisition::flight::video::VideoCodec;
use acquisition::recording::ImageEncoding;
use acquisition::sim::{record, record_flight, ScenarioArgs, Simulator};
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct SimulateArgs {
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Output folder for the recording (must not exist or be empty).
    #[arg(long, required_unless_present_any = ["list", "print", "flight_out"])]
    out: Option<PathBuf>,
    /// Write the scenario as a flight instead: per UAV a video and a MAVLink .tlog,
    /// flight.toml, and truth (docs/flight-io.md). Replay with `dualgeo run --source
    /// DIR/flight.toml`.
    #[arg(long, conflicts_with = "out")]
    flight_out: Option<PathBuf>,
    /// The flight's video encoding: `h264` (MP4, what a video link delivers) or
    /// `lossless` (FFV1 in MKV, to measure the flight path without compression).
    #[arg(long, default_value = "h264", value_parser = ["h264", "lossless"])]
    flight_video: String,
    /// Encode the flight's H.264 at this crf (0–51; 18 near-transparent, 28 a thin
    /// link) through FFmpeg's command-line tool instead of OpenCV's writer, whose H.264
    /// is always x264's default (crf 23).
    #[arg(long, conflicts_with = "out", value_parser = clap::value_parser!(u8).range(0..=51))]
    crf: Option<u8>,
    /// Write the recording's images as JPEG of this quality (1–100) instead of PNG:
    /// several times faster to decode on replay (docs/pipeline.md measures both).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=100), conflicts_with = "flight_out")]
    jpeg_quality: Option<u8>,
    /// List the presets and exit.
    #[arg(long)]
    list: bool,
    /// Print the preset, fully resolved, as TOML and exit.
    #[arg(long)]
    print: bool,
}

pub fn run(args: &SimulateArgs) -> Result<()> {
    let presets = args.scenario.presets()?;
    if args.list {
        for name in presets.names() {
            let description = presets
                .get(name)
                .map(|c| c.description)
                .unwrap_or_else(|e| format!("INVALID: {e}"));
            println!("{name:14} {description}");
        }
        return Ok(());
    }
    let config = args.scenario.config()?;
    if args.print {
        print!(
            "{}",
            toml::to_string(&config).context("serialising the preset")?
        );
        return Ok(());
    }
    let started = Instant::now();
    let mut sim = Simulator::new(config)?;
    let total = sim.frame_count();
    let bar = if std::io::stderr().is_terminal() {
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} rendering {pos}/{len} stereo pairs [{bar:30}] {per_sec} eta {eta}",
            )
            .context("progress template")?
            .progress_chars("=> "),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    let progress = |done: u64, total: u64| {
        bar.set_position(done);
        if bar.is_hidden() && (done.is_multiple_of(300) || done == total) {
            eprintln!("simulate: {done}/{total} stereo pairs");
        }
    };
    let (out, summary) = match (&args.out, &args.flight_out) {
        (_, Some(dir)) => {
            let codec = match (args.flight_video.as_str(), args.crf) {
                ("lossless", Some(_)) => {
                    anyhow::bail!(
                        "--crf sets H.264's quality: it does not go with --flight-video lossless"
                    )
                }
                ("lossless", None) => VideoCodec::Lossless,
                (_, Some(crf)) => VideoCodec::H264Crf(crf),
                (_, None) => VideoCodec::H264,
            };
            let (summary, codec) =
                record_flight(&mut sim, &args.scenario.preset, dir, codec, progress)
                    .with_context(|| format!("writing flight {}", dir.display()))?;
            eprintln!("simulate: videos encoded as {codec}");
            (dir.join("flight.toml"), summary)
        }
        (Some(out), None) => {
            let encoding = match args.jpeg_quality {
                Some(quality) => ImageEncoding::Jpeg { quality },
                None => ImageEncoding::Png,
            };
            let summary = record(&mut sim, &args.scenario.preset, out, encoding, progress)
                .with_context(|| format!("writing recording {}", out.display()))?;
            (out.clone(), summary)
        }
        (None, None) => anyhow::bail!("--out or --flight-out is required"),
    };
    bar.finish_and_clear();
    println!(
        "wrote {} ({} stereo pairs, {} x {}, {:.1} s) in {:.1} s; target outside the image in {} frames",
        out.display(),
        summary.frames_per_uav,
        sim.config().camera.width,
        sim.config().camera.height,
        sim.config().duration_s,
        started.elapsed().as_secs_f64(),
        summary.target_outside
    );
    Ok(())
}
