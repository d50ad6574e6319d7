//! `shapecast batch --dicomweb BASE [--query KEY=VALUE ...] --shard I/N`: the shape MIP and the
//! findings of every CT and MR series of an archive, stored back into each series' study, one
//! worker's share at a time.
//!
//! The series are found with QIDO-RS (`{base}/series?Modality=CT&...`, paged). A series belongs
//! to shard `fnv1a(SeriesInstanceUID) mod N`, so every worker agrees on the split whatever order
//! the archive answers in, and no scheduler of ours is needed: Kubernetes Indexed Jobs
//! (JOB_COMPLETION_INDEX, with `--shards N`) and Slurm job arrays (SLURM_ARRAY_TASK_ID,
//! SLURM_ARRAY_TASK_COUNT) give the shard (docs/batch.md). The results' UIDs are derived from the
//! source series and the settings (`stow::Rotation::stable_key`), so a series whose rotation is
//! already in the archive is skipped: a rerun or a restarted worker does no series twice and a
//! killed one loses at most the series it was on. The report (findings, CT only) is stored
//! before the rotation, whose presence marks the series done.

use anyhow::{Context as _, bail};

use crate::cli::dicomweb::DicomWebArgs;
use crate::compute::pipeline::{FeatureJob, JobOptions};
use crate::cpu::findings::{self, SHOWN};
use crate::cpu::pipeline::{Method, Request};
use crate::cpu::{Grid, Preset};
use crate::gpu::GpuContext;
use crate::io::dicomweb::client::Client;
use crate::io::dicomweb::{SeriesInfo, SeriesSearch, sr, stow};
use crate::volume::Modality;

#[derive(clap::Args, Debug)]
pub struct BatchArgs {
    /// The archive (its DICOMweb root), credentials and CA as for `info --dicomweb`; --study
    /// limits the batch to one study.
    #[command(flatten)]
    pub dicomweb: DicomWebArgs,
    /// A QIDO-RS matching key for the series, e.g. StudyDate=20240101-20240131 or
    /// BodyPartExamined=CHEST (repeatable; all must match).
    #[arg(long = "query", value_name = "KEY=VALUE")]
    pub query: Vec<String>,
    /// hessian, li, frangi, gst or rst (findings need blobness: hessian, li or rst).
    #[arg(long, default_value = "rst")]
    pub method: Method,
    /// lymph-nodes, lung-nodules, airways or vessels.
    #[arg(long, default_value = "lymph-nodes")]
    pub preset: String,
    /// This worker's share, I/N (0 <= I < N). Default: JOB_COMPLETION_INDEX with --shards
    /// (Kubernetes Indexed Job), else SLURM_ARRAY_TASK_ID of SLURM_ARRAY_TASK_COUNT (Slurm job
    /// array), else 0/1 (everything).
    #[arg(long, value_name = "I/N")]
    pub shard: Option<String>,
    /// The number of shards, for a Kubernetes Indexed Job (its completions).
    #[arg(long, value_name = "N")]
    pub shards: Option<u32>,
    /// Frames of the MIP's turn.
    #[arg(long, default_value_t = 36)]
    pub frames: u32,
    /// Frame size, WxH.
    #[arg(long, default_value = "512x512")]
    pub size: String,
    /// List this shard's series and whether each is done; compute and store nothing.
    #[arg(long)]
    pub dry_run: bool,
}

/// The modalities a batch processes.
const MODALITIES: [&str; 2] = ["CT", "MR"];
/// Series with fewer images are not volumes (localizers, dose pages) and are skipped.
const MIN_INSTANCES: u64 = 3;
/// Series asked for per QIDO page.
const PAGE: usize = 100;
/// The most pages read per modality (a million series).
const MAX_PAGES: usize = 10_000;

/// The shard a series belongs to (FNV-1a of its UID), the same in every worker.
fn shard_of(series_uid: &str, shards: u32) -> u32 {
    (stow::fnv1a(series_uid.as_bytes()) % u64::from(shards.max(1))) as u32
}

/// This worker's shard (index, count), from `--shard`, else the scheduler's environment.
pub fn shard(
    arg: Option<&str>,
    shards: Option<u32>,
    env: &dyn Fn(&str) -> Option<String>,
) -> anyhow::Result<(u32, u32)> {
    let parse = |name: &str, v: &str| -> anyhow::Result<u32> {
        v.trim()
            .parse::<u32>()
            .with_context(|| format!("{name}={v:?}: not a whole number"))
    };
    let (i, n, from) = if let Some(s) = arg {
        let (i, n) = s
            .split_once('/')
            .with_context(|| format!("--shard {s}: expected I/N, e.g. 0/4"))?;
        (parse("--shard", i)?, parse("--shard", n)?, "--shard")
    } else if let Some(index) = env("JOB_COMPLETION_INDEX") {
        let Some(n) = shards else {
            bail!(
                "JOB_COMPLETION_INDEX={index} (a Kubernetes Indexed Job) needs --shards N, the Job's completions"
            );
        };
        (
            parse("JOB_COMPLETION_INDEX", &index)?,
            n,
            "JOB_COMPLETION_INDEX",
        )
    } else if let Some(task) = env("SLURM_ARRAY_TASK_ID") {
        let count = env("SLURM_ARRAY_TASK_COUNT")
            .context("SLURM_ARRAY_TASK_ID without SLURM_ARRAY_TASK_COUNT")?;
        // Arrays may start anywhere (--array=1-10): the index counts from the first task.
        let min = match env("SLURM_ARRAY_TASK_MIN") {
            Some(m) => parse("SLURM_ARRAY_TASK_MIN", &m)?,
            None => 0,
        };
        let task = parse("SLURM_ARRAY_TASK_ID", &task)?;
        (
            task.checked_sub(min)
                .context("SLURM_ARRAY_TASK_ID below SLURM_ARRAY_TASK_MIN")?,
            parse("SLURM_ARRAY_TASK_COUNT", &count)?,
            "SLURM_ARRAY_TASK_ID",
        )
    } else {
        (0, shards.unwrap_or(1), "the default")
    };
    if n == 0 || i >= n {
        bail!("shard {i}/{n} (from {from}): need 0 <= I < N");
    }
    Ok((i, n))
}

/// A series to process.
struct Item {
    study: String,
    series: SeriesInfo,
}

/// Every CT and MR series the query matches, paged, in a stable order.
fn list_series(
    client: &Client,
    keys: &[(String, String)],
    study: Option<&str>,
) -> anyhow::Result<Vec<Item>> {
    let mut out = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for modality in MODALITIES {
        let mut offset = 0;
        for page in 0.. {
            if page == MAX_PAGES {
                bail!(
                    "more than {} {modality} series: narrow the query",
                    PAGE * MAX_PAGES
                );
            }
            let mut keys = keys.to_vec();
            if let Some(s) = study {
                keys.push(("StudyInstanceUID".to_owned(), s.to_owned()));
            }
            let search = SeriesSearch {
                modality: modality.to_owned(),
                keys,
                offset,
                limit: PAGE,
            };
            let found = client
                .search_series(&search)
                .with_context(|| format!("listing the {modality} series"))?;
            let n = found.len();
            let mut new = 0;
            for (study, series) in found {
                if !seen.insert(series.series_uid.clone()) {
                    continue;
                }
                new += 1;
                // A result of ours (a rotation is OT, a report SR) is never a source; an
                // archive that ignores the Modality key is held to it here.
                if series.modality.as_deref() == Some(modality) {
                    out.push(Item { study, series });
                }
            }
            // An archive that caps its answers below the page asked for ends a page early: ask
            // on until a page comes back empty, or (an archive that ignores `offset` and
            // answers the first page again) brings nothing new.
            if n == 0 || new == 0 {
                break;
            }
            offset += n;
        }
    }
    out.sort_by(|a, b| (&a.study, &a.series.series_uid).cmp(&(&b.study, &b.series.series_uid)));
    out.dedup_by(|a, b| a.series.series_uid == b.series.series_uid);
    Ok(out)
}

/// The settings a result's UIDs are derived from: the same settings give the same UIDs.
fn stable_key(args: &BatchArgs, preset: Preset, series: &str, what: &str) -> String {
    format!(
        "batch|{series}|{}|{}|{}|{}|{what}",
        args.method.name(),
        preset.name(),
        args.frames,
        args.size
    )
}

/// What one series gave.
struct Done {
    findings: Option<usize>,
    seconds: f64,
}

fn process(
    ctx: &GpuContext,
    client: &Client,
    args: &BatchArgs,
    preset: Preset,
    size: [u32; 2],
    item: &Item,
    rotation_uid_key: &str,
) -> anyhow::Result<Done> {
    let started = std::time::Instant::now();
    let (study, series) = (&item.study, &item.series.series_uid);
    let loaded = client
        .retrieve(study, series, &mut |_| {})
        .context("retrieving")?;
    let volume = std::sync::Arc::new(loaded.volume);
    // Findings read HU: a CT's, with a method that has blobness.
    let blobness = matches!(args.method, Method::Hessian | Method::Li | Method::Rst);
    let ct = volume.modality == Modality::Ct;
    let request = if blobness {
        crate::cli::findings::request(args.method, preset)?
    } else {
        let mut r = Request::new(args.method);
        r.preset = preset;
        r
    };
    let options = JobOptions {
        export: ct && blobness,
        ..JobOptions::default()
    };
    let mut job = FeatureJob::shared(ctx, std::sync::Arc::clone(&volume), &request, options)?;
    job.run_blocking(ctx)?;
    let result = job
        .finish_result()
        .context("the feature job did not finish")?;
    let source = client
        .source_series(study, series)
        .context("the series' metadata")?;
    let now = stow::DicomNow::now();
    let mut found = None;
    if let Some(components) = &result.components {
        let grid = Grid::of(&volume);
        let list = findings::find(&grid, &volume.to_f32(), &components[2], preset)?;
        let groups = crate::cli::findings::report_groups(&volume, &list.findings, preset, SHOWN);
        found = Some(groups.len());
        if !groups.is_empty() {
            let report = sr::Report {
                description: format!(
                    "findings, {} {} ({} candidates)",
                    args.method.name().to_uppercase(),
                    preset.name(),
                    groups.len()
                ),
                groups,
                stable_key: Some(stable_key(args, preset, series, "report")),
            };
            let instance =
                sr::measurement_report(&source, &report, &now, stow::REPORT_SERIES_NUMBER)?;
            let stored = client
                .store(study, std::slice::from_ref(&instance))
                .context("storing the report")?;
            for w in stored.warnings {
                eprintln!("  series {series}: the archive says of the report: {w}");
            }
        }
    }
    let frames = crate::cli::render::rotation_frames(
        ctx,
        &volume,
        Some(&result.texture),
        preset,
        size,
        args.frames,
    )?;
    let rotation = stow::Rotation {
        width: size[0],
        height: size[1],
        frames: &frames,
        description: format!(
            "shape MIP, {}, {}",
            args.method.name().to_uppercase(),
            preset.name()
        ),
        derivation: format!(
            "Shapecast {} batch: maximum intensity projection of the {} features ({} preset), {} views about the vertical axis from the anterior view",
            env!("CARGO_PKG_VERSION"),
            args.method.name().to_uppercase(),
            preset.name(),
            args.frames
        ),
        step_deg: 360.0 / f64::from(args.frames),
        stable_key: Some(rotation_uid_key.to_owned()),
    };
    let instance = stow::secondary_capture(&source, &rotation, &now, stow::ROTATION_SERIES_NUMBER)?;
    let stored = client
        .store(study, std::slice::from_ref(&instance))
        .context("storing the rotation")?;
    for w in stored.warnings {
        eprintln!("  series {series}: the archive says of the rotation: {w}");
    }
    Ok(Done {
        findings: found,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The rotation's series UID for a source series: what marks it done.
fn rotation_series_uid(key: &str) -> String {
    stow::uid_for(&format!("shapecast|stable|{key}|series"))
}

pub fn run(args: BatchArgs) -> anyhow::Result<()> {
    let Some(base) = args.dicomweb.dicomweb.clone() else {
        bail!("batch needs --dicomweb BASE");
    };
    if args.dicomweb.series.is_some() {
        bail!(
            "batch processes every series the query matches: --series is not used (--study limits it to a study)"
        );
    }
    let preset = crate::cli::preset(&args.preset)?;
    let size = crate::cli::render::parse_size(&args.size)?;
    if !(1..=360).contains(&args.frames) {
        bail!("--frames {}: give 1 to 360", args.frames);
    }
    let keys: Vec<(String, String)> = args
        .query
        .iter()
        .map(|q| SeriesSearch::parse_key(q))
        .collect::<Result<_, _>>()?;
    let (index, count) = shard(args.shard.as_deref(), args.shards, &|name| {
        std::env::var(name).ok().filter(|v| !v.trim().is_empty())
    })?;
    let client = args.dicomweb.client_for(&base)?;
    let started = std::time::Instant::now();
    let all = list_series(&client, &keys, args.dicomweb.study.as_deref())?;
    let mine: Vec<&Item> = all
        .iter()
        .filter(|i| shard_of(&i.series.series_uid, count) == index)
        .collect();
    eprintln!(
        "batch: {} CT/MR series match; shard {index}/{count} has {}",
        all.len(),
        mine.len()
    );
    let ctx = if args.dry_run {
        None
    } else {
        Some(pollster::block_on(GpuContext::new_headless())?)
    };
    let (mut done, mut skipped) = (0usize, 0usize);
    let mut failed = Vec::new();
    for (n, item) in mine.iter().enumerate() {
        let series = &item.series.series_uid;
        let what = format!(
            "[{}/{}] series {series} ({}, {} instances)",
            n + 1,
            mine.len(),
            item.series.modality.as_deref().unwrap_or("?"),
            item.series
                .instances
                .map_or("?".to_owned(), |i| i.to_string())
        );
        // A localizer or a dose page is no volume: not a failure, and not tried.
        if item.series.instances.is_some_and(|n| n < MIN_INSTANCES) {
            skipped += 1;
            eprintln!("{what}: skipped, fewer than {MIN_INSTANCES} images make no volume");
            continue;
        }
        let key = stable_key(&args, preset, series, "rotation");
        let result_uid = rotation_series_uid(&key);
        match client.has_series(&item.study, &result_uid) {
            Ok(true) => {
                skipped += 1;
                eprintln!("{what}: skipped, its result is in the archive (series {result_uid})");
                continue;
            }
            Ok(false) => {}
            Err(e) => {
                let e = crate::error::chain(&e);
                eprintln!("{what}: FAILED: asking whether it is done: {e}");
                failed.push((item, format!("asking whether it is done: {e}")));
                continue;
            }
        }
        let Some(ctx) = &ctx else {
            eprintln!("{what}: to do");
            continue;
        };
        match process(ctx, &client, &args, preset, size, item, &key) {
            Ok(d) => {
                done += 1;
                eprintln!(
                    "{what}: stored the rotation (series {result_uid}){} in {:.1} s",
                    match d.findings {
                        Some(0) => ", no findings".to_owned(),
                        Some(k) => format!(" and a report of {k} findings"),
                        None => String::new(),
                    },
                    d.seconds
                );
            }
            Err(e) => {
                let message = format!("{e:#}");
                eprintln!("{what}: FAILED: {message}");
                failed.push((item, message));
            }
        }
    }
    let summary = serde_json::json!({
        "shard": [index, count],
        "series_matching": all.len(),
        "series_in_shard": mine.len(),
        "done": done,
        "skipped": skipped,
        "to_do": if args.dry_run { mine.len() - skipped - failed.len() } else { 0 },
        "failed": failed
            .iter()
            .map(|(i, e)| serde_json::json!({
                "study": i.study,
                "series": i.series.series_uid,
                "error": e,
            }))
            .collect::<Vec<_>>(),
        "method": args.method.name(),
        "preset": preset.name(),
        "seconds": (started.elapsed().as_secs_f64() * 10.0).round() / 10.0,
    });
    println!("{}", serde_json::to_string_pretty(&summary)?);
    if !failed.is_empty() {
        bail!("{} of {} series failed", failed.len(), mine.len());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env_of(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let pairs: Vec<(String, String)> = pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect();
        move |name| {
            pairs
                .iter()
                .find(|(k, _)| k == name)
                .map(|(_, v)| v.clone())
        }
    }

    #[test]
    fn the_shard_comes_from_the_flag_or_the_scheduler() {
        let none = env_of(&[]);
        assert_eq!(shard(Some("1/4"), None, &none).ok(), Some((1, 4)));
        assert_eq!(shard(None, None, &none).ok(), Some((0, 1)));
        assert!(shard(Some("4/4"), None, &none).is_err());
        assert!(shard(Some("x"), None, &none).is_err());
        let k8s = env_of(&[("JOB_COMPLETION_INDEX", "2")]);
        assert_eq!(shard(None, Some(5), &k8s).ok(), Some((2, 5)));
        let e = shard(None, None, &k8s).expect_err("no count");
        assert!(e.to_string().contains("--shards"), "{e}");
        let slurm = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
        ]);
        assert_eq!(shard(None, None, &slurm).ok(), Some((2, 3)));
        // The flag wins over the environment.
        assert_eq!(shard(Some("0/2"), None, &slurm).ok(), Some((0, 2)));
    }

    #[test]
    fn every_series_is_in_exactly_one_shard() {
        let uids: Vec<String> = (0..200).map(|i| format!("1.2.840.{i}")).collect();
        let mut counts = [0usize; 4];
        for u in &uids {
            counts[shard_of(u, 4) as usize] += 1;
        }
        assert_eq!(counts.iter().sum::<usize>(), 200);
        assert!(counts.iter().all(|&c| c > 25), "{counts:?}");
        assert_eq!(shard_of("1.2.3", 1), 0);
    }
}
