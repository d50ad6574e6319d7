//! The DICOMweb client against a real archive: Debian's Orthanc with its DICOMweb plugin,
//! started on a free 127.0.0.1 port with a temporary storage folder, fed the DICOM series of
//! ../shared/data/series through its REST API, and stopped by its pid at the end (a Drop guard,
//! so also when a check fails). Where Orthanc or ../shared/data is missing the tests say so and
//! skip, except under CI=true, where that is a failure (`cargo xtask setup` installs Orthanc).
//! Two tests need neither: a connection refused, and an instance cut short by a tiny local
//! server.

use crate::common;

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use shapecast::io::dicomweb::client::{Client, Transport, UreqTransport};
use shapecast::io::dicomweb::{Auth, Base, DicomWebError, Request, Retrieval};
use shapecast::io::{InputFile, Limits};

fn ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Orthanc's binary and its DICOMweb plugin, or a visible skip (a failure under CI=true).
fn orthanc_install() -> Option<(PathBuf, PathBuf)> {
    let binary = ["/usr/sbin/Orthanc", "/usr/bin/Orthanc"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists());
    // Debian links the plugin into /usr/share/orthanc/plugins (`dpkg -L orthanc-dicomweb`).
    let plugin_dirs = ["/usr/share/orthanc/plugins", "/usr/lib/orthanc"];
    let plugin = plugin_dirs.iter().find_map(|d| {
        let mut found: Vec<PathBuf> = std::fs::read_dir(d)
            .ok()?
            .flatten()
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("libOrthancDicomWeb.so"))
            })
            .collect();
        found.sort();
        found.into_iter().next()
    });
    match (binary, plugin) {
        (Some(b), Some(p)) => Some((b, p)),
        (b, p) => {
            let what = format!(
                "Orthanc {} and its DICOMweb plugin {} (Debian packages orthanc, orthanc-dicomweb; `cargo xtask setup` installs them)",
                if b.is_some() { "found" } else { "missing" },
                if p.is_some() { "found" } else { "missing" }
            );
            if ci() {
                panic!("CI=true but {what}");
            }
            eprintln!("SKIPPED: {what}");
            None
        }
    }
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port on 127.0.0.1")
}

const USER: &str = "shapecast";
const PASSWORD: &str = "test-password";

/// A running Orthanc; dropping it kills the process by its pid and removes its folder.
struct Orthanc {
    child: Child,
    port: u16,
    dir: PathBuf,
    auth: bool,
    agent: ureq::Agent,
}

impl Drop for Orthanc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl Orthanc {
    /// Starts Orthanc with the DICOMweb plugin (and HTTP Basic authentication if `auth`).
    fn start(auth: bool) -> Option<Self> {
        Self::start_with(auth, None)
    }

    /// ... and with its answers capped at `limit` instances and results, as many archives are
    /// configured (`LimitFindInstances`, `LimitFindResults`).
    fn start_with(auth: bool, limit: Option<u32>) -> Option<Self> {
        let (binary, plugin) = orthanc_install()?;
        static N: AtomicUsize = AtomicUsize::new(0);
        let dir = std::env::temp_dir().join(format!(
            "shapecast-orthanc-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::SeqCst)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("db")).expect("temporary folder");
        let port = free_port();
        let config = serde_json::json!({
            "Name": "shapecast-test",
            "StorageDirectory": dir.join("db"),
            "IndexDirectory": dir.join("db"),
            "HttpPort": port,
            "DicomServerEnabled": false,
            "RemoteAccessAllowed": false,
            "AuthenticationEnabled": auth,
            "RegisteredUsers": if auth { serde_json::json!({ USER: PASSWORD }) } else { serde_json::json!({}) },
            "HttpCompressionEnabled": false,
            "Plugins": [plugin],
            "DicomWeb": { "Enable": true, "Root": "/dicom-web/" },
            "LimitFindInstances": limit.unwrap_or(0),
            "LimitFindResults": limit.unwrap_or(0),
        });
        let config_path = dir.join("orthanc.json");
        std::fs::write(
            &config_path,
            serde_json::to_vec_pretty(&config).unwrap_or_default(),
        )
        .expect("write the config");
        let log = std::fs::File::create(dir.join("orthanc.log")).expect("log file");
        let child = Command::new(&binary)
            .arg(&config_path)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("start Orthanc");
        let agent = ureq::Agent::new_with_config(
            ureq::Agent::config_builder()
                .http_status_as_error(false)
                .build(),
        );
        let mut o = Self {
            child,
            port,
            dir,
            auth,
            agent,
        };
        let started = Instant::now();
        loop {
            if let Ok(Some(status)) = o.child.try_wait() {
                panic!("Orthanc exited ({status}): {}", o.log());
            }
            if o.rest_get("/system").is_ok_and(|s| s == 200) {
                break;
            }
            if started.elapsed() > Duration::from_secs(30) {
                panic!("Orthanc did not answer within 30 s: {}", o.log());
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        Some(o)
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("orthanc.log")).unwrap_or_default()
    }

    fn url(&self, path: &str) -> String {
        format!("http://127.0.0.1:{}{path}", self.port)
    }

    fn base(&self) -> Base {
        Base::parse(&self.url("/dicom-web")).expect("base")
    }

    fn basic(&self) -> Option<String> {
        self.auth.then(|| {
            Auth::basic(&format!("{USER}:{PASSWORD}"))
                .ok()
                .and_then(|a| a.header())
                .unwrap_or_default()
        })
    }

    fn rest_get(&self, path: &str) -> Result<u16, ureq::Error> {
        let mut req = self.agent.get(self.url(path));
        if let Some(a) = self.basic() {
            req = req.header("Authorization", a);
        }
        Ok(req.call()?.status().as_u16())
    }

    fn rest_post(&self, path: &str, body: &[u8]) -> Vec<u8> {
        let mut req = self.agent.post(self.url(path));
        if let Some(a) = self.basic() {
            req = req.header("Authorization", a);
        }
        let mut resp = req
            .send(body)
            .unwrap_or_else(|e| panic!("POST {path}: {e}"));
        assert_eq!(resp.status().as_u16(), 200, "POST {path}");
        resp.body_mut()
            .with_config()
            .limit(64 << 20)
            .read_to_vec()
            .unwrap_or_else(|e| panic!("POST {path}: {e}"))
    }

    /// Uploads files (POST /instances, four at a time); returns Orthanc's instance IDs.
    fn upload(&self, files: &[PathBuf]) -> Vec<String> {
        let ids = std::sync::Mutex::new(vec![String::new(); files.len()]);
        let next = AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| {
                    loop {
                        let i = next.fetch_add(1, Ordering::SeqCst);
                        let Some(f) = files.get(i) else { return };
                        let bytes = std::fs::read(f).expect("read a DICOM file");
                        let answer = self.rest_post("/instances", &bytes);
                        let v: serde_json::Value =
                            serde_json::from_slice(&answer).expect("Orthanc's JSON");
                        if let Ok(mut ids) = ids.lock() {
                            ids[i] = v["ID"].as_str().unwrap_or_default().to_owned();
                        }
                    }
                });
            }
        });
        ids.into_inner().unwrap_or_default()
    }
}

/// The files of a ../shared/data series folder, sorted.
fn series_files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("series folder")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    v
}

/// StudyInstanceUID and SeriesInstanceUID of a DICOM file.
fn uids(path: &Path) -> (String, String) {
    let obj = dicom_object::open_file(path).expect("a DICOM file");
    let get = |name: &str| {
        obj.element_by_name(name)
            .ok()
            .and_then(|e| e.to_str().ok())
            .map(|s| s.trim_end_matches(['\0', ' ']).to_owned())
            .unwrap_or_default()
    };
    (get("StudyInstanceUID"), get("SeriesInstanceUID"))
}

fn shapecast(args: &[&str], env: &[(&str, &str)]) -> (bool, String, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_shapecast"));
    cmd.args(args)
        .env_remove("SHAPECAST_DICOMWEB_TOKEN")
        .env_remove("SHAPECAST_DICOMWEB_USER")
        .env_remove("SHAPECAST_DICOMWEB_CA");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().expect("run shapecast");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn orthanc_listing_retrieval_geometry_and_messages() {
    let Some(series_root) = common::shared_data("series") else {
        return;
    };
    let Some(orthanc) = Orthanc::start(false) else {
        return;
    };
    let chest_dir = series_root.join("ct-chest-lung-kernel");
    let chest = series_files(&chest_dir);
    let mut all = Vec::new();
    for name in [
        "ct-chest-lung-kernel",
        "ct-3slice-liver",
        "ct-head-64px",
        "mr-prostate-adc-oblique",
    ] {
        all.extend(series_files(&series_root.join(name)));
    }
    let t = Instant::now();
    let ids = orthanc.upload(&all);
    eprintln!(
        "uploaded {} files in {:.1} s",
        all.len(),
        t.elapsed().as_secs_f64()
    );
    let (study, series) = uids(&chest[0]);

    // The 3-slice liver CT copied into the chest study as a second series (Orthanc rewrites
    // the UIDs), so that the study lists two series and the chooser has to pick.
    let liver_series = "1.2.826.0.1.3680043.8.498.16016";
    for id in &ids[chest.len()..chest.len() + 3] {
        let modify = serde_json::json!({
            "Replace": {
                "StudyInstanceUID": study,
                "SeriesInstanceUID": liver_series,
                "PatientID": "Lung_Dx-A0002",
                "PatientName": "Lung_Dx-A0002",
                "StudyDate": "20070425",
            },
            "Force": true,
        });
        let copy = orthanc.rest_post(
            &format!("/instances/{id}/modify"),
            &serde_json::to_vec(&modify).unwrap_or_default(),
        );
        orthanc.rest_post("/instances", &copy);
    }

    let client = Client::new(orthanc.base(), Auth::None).expect("client");
    // QIDO-RS: the study and its two series; the chooser takes the 30-slice CT.
    let resolved = client.resolve(&study, None).expect("resolve");
    assert_eq!(resolved.study.study_uid, study);
    assert_eq!(resolved.study.patient_id.as_deref(), Some("Lung_Dx-A0002"));
    assert_eq!(resolved.study.study_date.as_deref(), Some("20070425"));
    assert_eq!(resolved.series.len(), 2, "{:?}", resolved.series);
    let chosen = &resolved.series[resolved.chosen];
    assert!(resolved.by_chooser);
    assert_eq!(chosen.series_uid, series);
    assert_eq!(chosen.modality.as_deref(), Some("CT"));
    assert_eq!(chosen.instances, Some(30));
    assert_eq!(chosen.slice_thickness_mm, Some(8.0));
    assert_eq!(
        chosen.description.as_deref(),
        Some("ThoraxRoutine  8.0.0  B70f")
    );
    let liver = resolved
        .series
        .iter()
        .find(|s| s.series_uid == liver_series)
        .expect("the copied series is listed");
    assert_eq!(liver.instances, Some(3));
    assert_eq!(liver.slice_thickness_mm, Some(1.25));
    let instances = client.list_instances(&study, &series).expect("instances");
    assert_eq!(instances.len(), 30);

    // WADO-RS: the series equals the file loader's volume of the same folder, voxel for voxel.
    let t = Instant::now();
    let mut reports = 0;
    let got = client
        .retrieve(&study, &series, &mut |_| reports += 1)
        .expect("retrieve");
    let retrieve_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let files: Vec<InputFile> = chest.iter().map(|p| common::input(p)).collect();
    let want = shapecast::io::load(&files).expect("file loader");
    let disk_s = t.elapsed().as_secs_f64();
    eprintln!(
        "ct-chest-lung-kernel (30 x 512x512): DICOMweb retrieval {retrieve_s:.2} s, files from disk {disk_s:.2} s"
    );
    assert_eq!(reports, 30);
    assert_eq!(got.volume.dims, [512, 512, 30]);
    assert!(
        got.volume.source.starts_with("DICOMweb http://127.0.0.1:"),
        "{}",
        got.volume.source
    );
    let mut got_volume = got.volume.clone();
    got_volume.source = want.volume.source.clone();
    assert!(got_volume == want.volume, "the volumes differ");
    assert_eq!(got.volume.spacing_mm, want.volume.spacing_mm);
    assert_eq!(got.volume.origin_mm, want.volume.origin_mm);
    assert_eq!(got.volume.direction, want.volume.direction);

    // A study the archive does not hold, a series not in the study.
    let e = client
        .resolve("1.2.826.0.1.3680043.8.498.999", None)
        .expect_err("an error")
        .to_string();
    assert!(
        e.starts_with("study 1.2.826.0.1.3680043.8.498.999 not found"),
        "{e}"
    );
    let e = client
        .resolve(&study, Some("1.2.3.4"))
        .expect_err("an error")
        .to_string();
    assert!(
        e.contains("has no series 1.2.3.4") && e.contains(&series),
        "{e}"
    );
    let e = client
        .retrieve(&study, "1.2.3.4", &mut |_| {})
        .expect_err("an error")
        .to_string();
    assert!(e.contains("lists no instances"), "{e}");

    // A syntax this build cannot decode, as Orthanc sends it when asked (JPEG-LS): named.
    let transport = UreqTransport::new(1);
    let url = orthanc
        .base()
        .instance_url(&study, &series, &instances[0].sop_uid)
        .expect("url");
    let mut request = Request::wado(url, &Auth::None);
    request.headers[0].1 =
        "multipart/related; type=\"application/dicom\"; transfer-syntax=1.2.840.10008.1.2.4.80"
            .to_owned();
    let response = transport.get(&request).expect("JPEG-LS answer");
    assert_eq!(response.status, 200);
    let mut body = Vec::new();
    let (ct, mut reader) = (response.content_type, response.body);
    reader.read_to_end(&mut body).expect("body");
    let mut retrieval = Retrieval::new(
        orthanc.base(),
        &study,
        &series,
        instances[..1].to_vec(),
        Auth::None,
        Limits::default(),
    )
    .expect("retrieval");
    let fetch = retrieval.next_fetch().expect("a fetch");
    let mut parts = Vec::new();
    let mut parser = shapecast::io::dicomweb::MultipartParser::new(
        ct.as_deref(),
        "jpeg-ls",
        retrieval.multipart_limits(),
    )
    .expect("multipart");
    parser
        .feed(&body, &mut |p| {
            parts.push(p);
            Ok(())
        })
        .expect("parse");
    parser
        .finish(&mut |p| {
            parts.push(p);
            Ok(())
        })
        .expect("parse");
    assert_eq!(parts.len(), 1);
    let e = shapecast::error::chain(&retrieval.received(fetch.id, parts).expect_err("an error"));
    assert!(
        e.contains("1.2.840.10008.1.2.4.80")
            && e.contains("JPEG-LS")
            && e.contains("instance 1 of 1"),
        "{e}"
    );

    // The command line: the series list on stderr, the volume as `info --json` on the folder.
    let base = orthanc.url("/dicom-web");
    let (ok, stdout, stderr) = shapecast(
        &["info", "--json", "--dicomweb", &base, "--study", &study],
        &[],
    );
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("2 series:") && stderr.contains("* CT     30 instances, 8 mm"),
        "{stderr}"
    );
    assert!(stderr.contains(liver_series), "{stderr}");
    let (ok, disk_stdout, stderr_disk) =
        shapecast(&["info", "--json", &chest_dir.to_string_lossy()], &[]);
    assert!(ok, "{stderr_disk}");
    let web: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    let disk: serde_json::Value = serde_json::from_str(&disk_stdout).expect("JSON");
    for key in [
        "dims",
        "spacing_mm",
        "origin_mm",
        "direction",
        "min",
        "max",
        "voxel_type",
        "modality",
        "warnings",
    ] {
        assert_eq!(web[key], disk[key], "{key}");
    }
    // With --series: no list, the named series.
    let (ok, stdout, stderr) = shapecast(
        &[
            "info",
            "--json",
            "--dicomweb",
            &base,
            "--study",
            &study,
            "--series",
            liver_series,
        ],
        &[],
    );
    assert!(ok, "{stderr}");
    assert!(!stderr.contains("series:"), "{stderr}");
    let liver: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    assert_eq!(liver["dims"], serde_json::json!([512, 512, 3]));
    let (ok, _, stderr) = shapecast(&["info", "--dicomweb", &base, "--study", "1.2.3.4.5"], &[]);
    assert!(
        !ok && stderr.contains("study 1.2.3.4.5 not found"),
        "{stderr}"
    );
}

/// An archive whose QIDO answers are capped (`LimitFindInstances: 40`; Orthanc then lists 41
/// of the head CT's 93 instances and ignores `offset` past its cap): the client and
/// `shapecast info --dicomweb BASE/studies/UID/series/UID` (VolView's link form) complete the
/// list from the series metadata and open all 93 slices, never 41.
#[test]
fn orthanc_with_capped_answers_opens_whole_series() {
    let Some(series_root) = common::shared_data("series") else {
        return;
    };
    let Some(orthanc) = Orthanc::start_with(false, Some(40)) else {
        return;
    };
    let head = series_files(&series_root.join("ct-head-64px"));
    assert_eq!(head.len(), 93);
    orthanc.upload(&head);
    let (study, series) = uids(&head[0]);
    let base = orthanc.base();
    let capped = format!(
        "{}/studies/{study}/series/{series}/instances",
        base.as_str()
    );
    let listed: serde_json::Value = serde_json::from_slice(
        &orthanc
            .agent
            .get(&capped)
            .call()
            .expect("QIDO")
            .body_mut()
            .read_to_vec()
            .expect("QIDO body"),
    )
    .expect("QIDO JSON");
    let n = listed.as_array().map_or(0, Vec::len);
    assert!(n < 93, "this Orthanc does not cap its answers ({n} listed)");
    let client = Client::new(base.clone(), Auth::None).expect("client");
    assert_eq!(
        client
            .list_instances(&study, &series)
            .expect("listing")
            .len(),
        93
    );
    let loaded = client
        .retrieve(&study, &series, &mut |_| {})
        .expect("retrieve");
    assert_eq!(loaded.volume.dims, [64, 64, 93]);
    // The CLI, given the series as VolView links it (a URL into the series, no --study).
    let into_series = format!("{}/studies/{study}/series/{series}", base.as_str());
    let (ok, out, err) = shapecast(&["info", "--json", "--dicomweb", &into_series], &[]);
    assert!(ok, "{err}");
    let info: serde_json::Value = serde_json::from_str(&out).expect("info JSON");
    assert_eq!(info["dims"], serde_json::json!([64, 64, 93]), "{out}");
}

/// A TLS front for a plain-HTTP server on 127.0.0.1 (as a hospital's gateway terminates TLS
/// for its archive): one request per connection, forwarded with `Connection: close` and its
/// answer sent back whole. Its certificate, for 127.0.0.1, is made on the spot; `ca_pem` is
/// the certificate to trust.
struct TlsFront {
    port: u16,
    ca_pem: String,
}

impl TlsFront {
    fn start(upstream: u16) -> Self {
        let cert = rcgen::generate_simple_self_signed(vec!["127.0.0.1".to_owned()])
            .expect("a certificate");
        let key = rustls::pki_types::PrivateKeyDer::Pkcs8(cert.key_pair.serialize_der().into());
        let config = Arc::new(
            rustls::ServerConfig::builder_with_provider(Arc::new(
                rustls::crypto::ring::default_provider(),
            ))
            .with_safe_default_protocol_versions()
            .expect("TLS versions")
            .with_no_client_auth()
            .with_single_cert(vec![cert.cert.der().clone()], key)
            .expect("the server's certificate"),
        );
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = listener.local_addr().expect("address").port();
        std::thread::spawn(move || {
            for tcp in listener.incoming().flatten() {
                let config = config.clone();
                std::thread::spawn(move || Self::forward(tcp, config, upstream));
            }
        });
        Self {
            port,
            ca_pem: cert.cert.pem(),
        }
    }

    fn forward(tcp: TcpStream, config: Arc<rustls::ServerConfig>, upstream: u16) {
        let Ok(conn) = rustls::ServerConnection::new(config) else {
            return;
        };
        let mut tls = rustls::StreamOwned::new(conn, tcp);
        let mut head = Vec::new();
        let mut byte = [0u8; 1];
        while !head.ends_with(b"\r\n\r\n") {
            match tls.read(&mut byte) {
                Ok(1) => head.push(byte[0]),
                _ => return, // a refused handshake or a closed connection
            }
        }
        let head = String::from_utf8_lossy(&head);
        let mut request: String = head
            .split("\r\n")
            .filter(|l| !l.is_empty() && !l.to_ascii_lowercase().starts_with("connection:"))
            .map(|l| format!("{l}\r\n"))
            .collect();
        request.push_str("Connection: close\r\n\r\n");
        let Ok(mut up) = TcpStream::connect(("127.0.0.1", upstream)) else {
            return;
        };
        let mut answer = Vec::new();
        if up.write_all(request.as_bytes()).is_ok() && up.read_to_end(&mut answer).is_ok() {
            // The answer says the connection closes after it (the client must not reuse it).
            let Some(end) = answer.windows(4).position(|w| w == b"\r\n\r\n") else {
                return;
            };
            let head = String::from_utf8_lossy(&answer[..end]).into_owned();
            let mut head: String = head
                .split("\r\n")
                .filter(|l| !l.to_ascii_lowercase().starts_with("connection:"))
                .map(|l| format!("{l}\r\n"))
                .collect();
            head.push_str("Connection: close\r\n\r\n");
            let _ = tls.write_all(head.as_bytes());
            let _ = tls.write_all(&answer[end + 4..]);
            tls.conn.send_close_notify();
            let _ = tls.flush();
        }
    }
}

/// An https archive (Orthanc behind a TLS front with a certificate of the site's own CA):
/// `info --dicomweb https://...` refuses it without that CA (naming the certificate problem)
/// and opens the series with `--ca` (and with SHAPECAST_DICOMWEB_CA).
#[test]
fn an_https_archive_opens_with_the_site_s_ca() {
    let Some(series_root) = common::shared_data("series") else {
        return;
    };
    let Some(orthanc) = Orthanc::start(false) else {
        return;
    };
    let mr = series_files(&series_root.join("mr-prostate-adc-oblique"));
    orthanc.upload(&mr);
    let (study, series) = uids(&mr[0]);
    let front = TlsFront::start(orthanc.port);
    let ca = orthanc.dir.join("ca.pem");
    std::fs::write(&ca, &front.ca_pem).expect("write the CA");
    let url = format!(
        "https://127.0.0.1:{}/dicom-web/studies/{study}/series/{series}",
        front.port
    );
    let (ok, _, err) = shapecast(&["info", "--json", "--dicomweb", &url], &[]);
    assert!(!ok, "an unknown issuer was trusted");
    assert!(
        err.contains("cannot connect to 127.0.0.1") && err.to_lowercase().contains("certificate"),
        "{err}"
    );
    let ca_path = ca.to_string_lossy().into_owned();
    let (ok, out, err) = shapecast(
        &["info", "--json", "--dicomweb", &url, "--ca", &ca_path],
        &[],
    );
    assert!(ok, "{err}");
    let info: serde_json::Value = serde_json::from_str(&out).expect("info JSON");
    assert_eq!(info["dims"], serde_json::json!([256, 256, 20]), "{out}");
    let (ok, _, err) = shapecast(
        &["info", "--json", "--dicomweb", &url],
        &[("SHAPECAST_DICOMWEB_CA", &ca_path)],
    );
    assert!(ok, "{err}");
}

#[test]
fn orthanc_with_authentication() {
    let Some(series_root) = common::shared_data("series/ct-3slice-liver") else {
        return;
    };
    let Some(orthanc) = Orthanc::start(true) else {
        return;
    };
    let files = series_files(&series_root);
    orthanc.upload(&files);
    let (study, series) = uids(&files[0]);
    let base = orthanc.base();

    let e = Client::new(base.clone(), Auth::None)
        .expect("client")
        .resolve(&study, None)
        .expect_err("an error");
    assert!(
        matches!(e, DicomWebError::Unauthorized { status: 401, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("asks for credentials"), "{e}");
    // Orthanc knows Basic authentication only: a bearer token is refused, and said so.
    let token = Auth::bearer("not-a-real-token").expect("token");
    let e = Client::new(base.clone(), token)
        .expect("client")
        .resolve(&study, None)
        .expect_err("an error")
        .to_string();
    assert!(
        e.contains("401") && e.contains("did not accept the bearer token"),
        "{e}"
    );
    assert!(!e.contains("not-a-real-token"), "{e}");
    let wrong = Auth::basic(&format!("{USER}:wrong")).expect("user");
    let e = Client::new(base.clone(), wrong)
        .expect("client")
        .resolve(&study, None)
        .expect_err("an error")
        .to_string();
    assert!(
        e.contains("did not accept the user name and password"),
        "{e}"
    );

    let right = Auth::basic(&format!("{USER}:{PASSWORD}")).expect("user");
    let client = Client::new(base, right).expect("client");
    let r = client.resolve(&study, None).expect("resolve");
    assert_eq!(r.series[r.chosen].series_uid, series);
    let got = client
        .retrieve(&study, &series, &mut |_| {})
        .expect("retrieve");
    let inputs: Vec<InputFile> = files.iter().map(|p| common::input(p)).collect();
    let mut want = shapecast::io::load(&inputs).expect("file loader").volume;
    want.source = got.volume.source.clone();
    assert!(got.volume == want, "the volumes differ");

    // The command line asks for a token, and takes credentials from the environment.
    let url = orthanc.url("/dicom-web");
    let (ok, _, stderr) = shapecast(&["info", "--dicomweb", &url, "--study", &study], &[]);
    assert!(!ok, "{stderr}");
    assert!(
        stderr.contains("401") && stderr.contains("--token") && stderr.contains("--user"),
        "{stderr}"
    );
    let user = format!("{USER}:{PASSWORD}");
    let (ok, stdout, stderr) = shapecast(
        &["info", "--json", "--dicomweb", &url, "--study", &study],
        &[("SHAPECAST_DICOMWEB_USER", &user)],
    );
    assert!(ok, "{stderr}");
    assert!(stdout.contains("\"dims\""), "{stdout}");
    // STOW-RS with the same credentials stores a result; without them it is refused.
    use shapecast::io::dicomweb::stow;
    let source = client.source_series(&study, &series).expect("metadata");
    assert_eq!(source.instances.len(), files.len());
    let frames = vec![vec![200u8; 8 * 8 * 4]; 2];
    let rotation = stow::Rotation {
        width: 8,
        height: 8,
        frames: &frames,
        description: "shape MIP, test".to_owned(),
        derivation: "a test".to_owned(),
        step_deg: 180.0,
        stable_key: None,
    };
    let made = stow::secondary_capture(&source, &rotation, &stow::DicomNow::now(), 9001)
        .expect("the instance");
    let anonymous = Client::new(orthanc.base(), Auth::None).expect("client");
    let e = anonymous
        .store(&study, std::slice::from_ref(&made))
        .expect_err("stored without credentials");
    assert!(matches!(e, DicomWebError::Unauthorized { .. }), "{e}");
    let stored = client
        .store(&study, std::slice::from_ref(&made))
        .expect("stored");
    assert_eq!(stored.instances, vec![made.sop_instance_uid.clone()]);
    assert!(
        listed_series(&orthanc, &study)
            .iter()
            .any(|s| s.0 == made.series_uid && s.2 == "Shapecast shape MIP, test"),
        "not listed"
    );
}

/// The study's series as QIDO-RS lists them: (SeriesInstanceUID, Modality, SeriesDescription).
fn listed_series(orthanc: &Orthanc, study: &str) -> Vec<(String, String, String)> {
    let mut req = orthanc
        .agent
        .get(orthanc.url(&format!("/dicom-web/studies/{study}/series")));
    if let Some(a) = orthanc.basic() {
        req = req.header("Authorization", a);
    }
    let body = req
        .call()
        .expect("QIDO")
        .body_mut()
        .read_to_vec()
        .expect("QIDO body");
    let v: serde_json::Value = serde_json::from_slice(&body).expect("QIDO JSON");
    let text = |s: &serde_json::Value, tag: &str| {
        s[tag]["Value"][0].as_str().unwrap_or_default().to_owned()
    };
    v.as_array()
        .map(|a| {
            a.iter()
                .map(|s| {
                    (
                        text(s, "0020000E"),
                        text(s, "00080060"),
                        text(s, "0008103E"),
                    )
                })
                .collect()
        })
        .unwrap_or_default()
}

/// The DICOM file of the one instance of a series, through Orthanc's REST API.
fn instance_file(orthanc: &Orthanc, series: &str) -> Vec<u8> {
    let query = serde_json::json!({"Level": "Instance", "Query": {"SeriesInstanceUID": series}});
    let ids: Vec<String> = serde_json::from_slice(&orthanc.rest_post(
        "/tools/find",
        &serde_json::to_vec(&query).unwrap_or_default(),
    ))
    .expect("Orthanc's JSON");
    assert_eq!(ids.len(), 1, "{ids:?}");
    let mut req = orthanc
        .agent
        .get(orthanc.url(&format!("/instances/{}/file", ids[0])));
    if let Some(a) = orthanc.basic() {
        req = req.header("Authorization", a);
    }
    req.call()
        .expect("GET the file")
        .body_mut()
        .with_config()
        .limit(256 << 20)
        .read_to_vec()
        .expect("the file")
}

/// `render --dicomweb ... --turntable N --store` stores the rotation into the source study as
/// one multi-frame true-colour Secondary Capture: QIDO lists it (OT, "Shapecast shape MIP,
/// ..."), and read back with dicom-rs its frames are the PNG frames written beside, pixel for
/// pixel, with the source series referenced and the patient copied.
#[test]
fn a_shape_mip_rotation_is_stored_back_into_its_study() {
    let Some(series_root) = common::shared_data("series") else {
        return;
    };
    let Some(orthanc) = Orthanc::start(false) else {
        return;
    };
    let head = series_files(&series_root.join("ct-head-64px"));
    orthanc.upload(&head);
    let (study, series) = uids(&head[0]);
    let before = listed_series(&orthanc, &study);
    assert_eq!(before.len(), 1);
    let out = orthanc.dir.join("frames");
    let out_s = out.to_string_lossy().into_owned();
    let url = orthanc.url("/dicom-web");
    let (ok, _, err) = shapecast(
        &[
            "render",
            "--dicomweb",
            &url,
            "--study",
            &study,
            "--series",
            &series,
            "--method",
            "hessian",
            "--size",
            "48x40",
            "--turntable",
            "4",
            "--store",
            "--out",
            &out_s,
        ],
        &[],
    );
    assert!(ok, "{err}");
    assert!(err.contains("stored 4 frames"), "{err}");
    let after = listed_series(&orthanc, &study);
    assert_eq!(after.len(), 2, "{after:?}");
    let (sc_series, modality, description) = after
        .iter()
        .find(|s| s.0 != series)
        .cloned()
        .expect("the new series");
    assert_eq!(modality, "OT");
    assert!(
        description.starts_with("Shapecast shape MIP, Hessian"),
        "{description}"
    );
    assert!(err.contains(&sc_series), "{err}");

    let file = instance_file(&orthanc, &sc_series);
    let obj = dicom_object::from_reader(&file[128..]).expect("a DICOM file");
    let get = |name: &str| {
        obj.element_by_name(name)
            .ok()
            .and_then(|e| e.to_str().ok())
            .map(|s| s.trim_end_matches(['\0', ' ']).to_owned())
            .unwrap_or_default()
    };
    assert_eq!(get("SOPClassUID"), "1.2.840.10008.5.1.4.1.1.7.4");
    assert_eq!(get("NumberOfFrames"), "4");
    assert_eq!(get("Rows"), "40");
    assert_eq!(get("Columns"), "48");
    assert_eq!(get("PhotometricInterpretation"), "RGB");
    let source = dicom_object::open_file(&head[0]).expect("the source");
    let source_name = source
        .element_by_name("PatientID")
        .ok()
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim_end_matches(['\0', ' ']).to_owned())
        .unwrap_or_default();
    assert_eq!(get("PatientID"), source_name);
    let refs = obj
        .element_by_name("ReferencedSeriesSequence")
        .expect("ReferencedSeriesSequence");
    let item = &refs.items().expect("items")[0];
    let referenced = item
        .element_by_name("SeriesInstanceUID")
        .ok()
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim_end_matches(['\0', ' ']).to_owned());
    assert_eq!(referenced.as_deref(), Some(series.as_str()));
    let instances = item
        .element_by_name("ReferencedInstanceSequence")
        .expect("ReferencedInstanceSequence");
    assert_eq!(instances.items().map_or(0, |i| i.len()), 93);
    let pixels = obj
        .element_by_name("PixelData")
        .expect("PixelData")
        .to_bytes()
        .expect("pixels")
        .into_owned();
    assert_eq!(pixels.len(), 4 * 48 * 40 * 3);
    let mut lit = 0;
    for f in 0..4 {
        let png = image::open(out.join(format!("frame_{f:04}.png")))
            .expect("a frame")
            .to_rgb8();
        let frame = &pixels[f * 48 * 40 * 3..(f + 1) * 48 * 40 * 3];
        assert!(png.as_raw().as_slice() == frame, "frame {f} differs");
        lit += frame.iter().filter(|&&v| v > 40).count();
    }
    assert!(lit > 1000, "the frames are dark ({lit} bright samples)");

    // pydicom, another reader, decodes it as a viewer would.
    let path = orthanc.dir.join("stored.dcm");
    std::fs::write(&path, &file).expect("write the file");
    if let Some(read) = pydicom_read_back(&path) {
        assert_eq!(read["shape"], serde_json::json!([4, 40, 48, 3]), "{read}");
        assert_eq!(read["study"], serde_json::json!(study), "{read}");
        assert_eq!(
            read["referenced_series"],
            serde_json::json!(series),
            "{read}"
        );
        assert_eq!(read["source_images"], serde_json::json!(93), "{read}");
        let sum: u64 = pixels.iter().map(|&v| u64::from(v)).sum();
        assert_eq!(read["sum"], serde_json::json!(sum), "{read}");
        assert!(
            read["frame_time_ms"].as_f64().is_some_and(|t| t > 0.0),
            "{read}"
        );
    }
}

/// `findings --dicomweb ... --store`: the candidates listed go into the study as a TID 1500
/// measurement report (a Comprehensive 3D SR), which QIDO lists and pydicom reads back: one
/// "Finding" group per candidate, its diameter and its 3D point as the JSON listed them.
#[test]
fn findings_go_back_as_a_measurement_report() {
    let Some(series_root) = common::shared_data("series") else {
        return;
    };
    let Some(orthanc) = Orthanc::start(false) else {
        return;
    };
    let chest = series_files(&series_root.join("ct-chest-lung-kernel"));
    orthanc.upload(&chest);
    let (study, series) = uids(&chest[0]);
    let url = orthanc.url("/dicom-web");
    let (ok, out, err) = shapecast(
        &[
            "findings",
            "--dicomweb",
            &url,
            "--study",
            &study,
            "--series",
            &series,
            "--method",
            "hessian",
            "--preset",
            "lung-nodules",
            "--backend",
            "gpu",
            "--json",
            "--store",
        ],
        &[],
    );
    assert!(ok, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).expect("findings JSON");
    let list = json["findings"].as_array().expect("findings");
    assert!(!list.is_empty(), "no findings on the chest CT: {err}");
    assert!(
        err.contains(&format!("stored the report ({} groups)", list.len())),
        "{err}"
    );
    let listed = listed_series(&orthanc, &study);
    let (sr, _, description) = listed
        .iter()
        .find(|s| s.1 == "SR")
        .cloned()
        .unwrap_or_else(|| panic!("no SR listed: {listed:?}"));
    assert_eq!(
        description,
        format!(
            "Shapecast findings, HESSIAN lung-nodules ({} candidates)",
            list.len()
        )
    );
    let path = orthanc.dir.join("findings.dcm");
    std::fs::write(&path, instance_file(&orthanc, &sr)).expect("write the report");
    let obj = dicom_object::open_file(&path).expect("dicom-rs reads it");
    assert_eq!(
        obj.element_by_name("SOPClassUID")
            .ok()
            .and_then(|e| e.to_str().ok())
            .map(|s| s.trim_end_matches('\0').to_owned())
            .as_deref(),
        Some("1.2.840.10008.5.1.4.1.1.88.34")
    );
    let Some(read) = pydicom_read_back(&path) else {
        return;
    };
    assert_eq!(read["evidence_series"], serde_json::json!(series), "{read}");
    let groups = read["groups"].as_array().expect("groups");
    assert_eq!(groups.len(), list.len());
    let items = groups[0]["items"].as_array().expect("items");
    let find = |name: &str| {
        items
            .iter()
            .find(|i| i["concept"] == name)
            .unwrap_or_else(|| panic!("no {name} in {items:?}"))
    };
    assert_eq!(find("Tracking Identifier")["text"], "candidate 1");
    assert_eq!(find("Finding")["code"], "Nodule");
    let diameter = find("Diameter");
    let want = list[0]["diameter_mm"].as_f64().expect("diameter");
    assert!(
        (diameter["value"].as_f64().unwrap_or(0.0) - want).abs() < 0.01,
        "{diameter} vs {want}"
    );
    let point = &diameter["items"][0];
    assert_eq!(point["graphic_type"], "POINT");
    let lps = list[0]["lps_mm"].as_array().expect("lps");
    for (got, want) in point["points"].as_array().expect("points").iter().zip(lps) {
        let (g, w) = (
            got.as_f64().unwrap_or(f64::NAN),
            want.as_f64().unwrap_or(0.0),
        );
        assert!((g - w).abs() < 0.01, "{point} vs {lps:?}");
    }
}

/// A `shapecast batch` process with its stderr read line by line as it runs.
fn spawn_batch(url: &str, extra: &[&str], env: &[(&str, &str)]) -> Child {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_shapecast"));
    cmd.args([
        "batch",
        "--dicomweb",
        url,
        "--method",
        "hessian",
        "--preset",
        "lung-nodules",
        "--frames",
        "3",
        "--size",
        "40x32",
    ])
    .args(extra)
    .env_remove("SHAPECAST_DICOMWEB_TOKEN")
    .env_remove("SHAPECAST_DICOMWEB_USER")
    .env_remove("SHAPECAST_DICOMWEB_CA")
    .env_remove("JOB_COMPLETION_INDEX")
    .env_remove("SLURM_ARRAY_TASK_ID")
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.spawn().expect("start shapecast batch")
}

/// A batch process to its end: (success, the JSON summary, stderr).
fn finish_batch(child: Child) -> (bool, serde_json::Value, String) {
    let out = child.wait_with_output().expect("wait for shapecast batch");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    eprintln!("{err}");
    let summary = serde_json::from_slice(&out.stdout).unwrap_or(serde_json::Value::Null);
    (out.status.success(), summary, err)
}

/// `batch` over an archive that caps its answers at 2 (so the series search pages), holding a
/// head CT, a chest CT and an MR: a worker killed after its first series, then two shards run at
/// once (by the flag and from a Kubernetes Indexed Job's environment), then a rerun of both from
/// a Slurm array's environment. Every source series ends with exactly one rotation in its study
/// (the chest CT also its findings' report), the shards split the work, and the rerun does
/// nothing.
#[test]
fn a_batch_killed_restarted_and_sharded_stores_each_result_once() {
    let Some(series_root) = common::shared_data("series") else {
        return;
    };
    if shapecast::gpu::context::test_context().is_none() {
        return;
    }
    let Some(orthanc) = Orthanc::start_with(false, Some(2)) else {
        return;
    };
    let head = series_files(&series_root.join("ct-head-64px"));
    let mr = series_files(&series_root.join("mr-prostate-adc-oblique"));
    let chest = series_files(&series_root.join("ct-chest-lung-kernel"));
    for files in [&head, &mr, &chest] {
        orthanc.upload(files);
    }
    let url = orthanc.url("/dicom-web");
    let count = |v: &serde_json::Value, key: &str| v[key].as_u64().unwrap_or(u64::MAX);

    // A worker killed once it has stored its first series.
    let mut killed = spawn_batch(&url, &["--shard", "0/1"], &[]);
    let stderr = killed.stderr.take().expect("stderr");
    let mut first = String::new();
    for line in std::io::BufRead::lines(std::io::BufReader::new(stderr)) {
        let Ok(line) = line else { break };
        eprintln!("{line}");
        if line.contains("stored the rotation") {
            first = line;
            break;
        }
    }
    let _ = killed.kill();
    let _ = killed.wait();
    assert!(
        first.starts_with("[1/3]"),
        "the killed worker stored nothing first: {first:?}"
    );

    // Two shards at once finish the rest.
    let a = spawn_batch(&url, &["--shard", "0/2"], &[]);
    let b = spawn_batch(&url, &["--shards", "2"], &[("JOB_COMPLETION_INDEX", "1")]);
    let (ok_a, sa, err_a) = finish_batch(a);
    let (ok_b, sb, err_b) = finish_batch(b);
    assert!(ok_a && ok_b, "{err_a}\n{err_b}");
    assert_eq!(count(&sa, "series_matching"), 3, "{sa}");
    assert_eq!(count(&sb, "series_matching"), 3, "{sb}");
    assert_eq!(
        count(&sa, "series_in_shard") + count(&sb, "series_in_shard"),
        3
    );
    // The killed worker's series is skipped; the other two are done.
    assert_eq!(count(&sa, "done") + count(&sb, "done"), 2, "{sa} {sb}");
    assert_eq!(
        count(&sa, "skipped") + count(&sb, "skipped"),
        1,
        "{sa} {sb}"
    );

    // Exactly one rotation per source series, and the chest CT's report.
    for (files, name) in [(&head, "head CT"), (&mr, "MR"), (&chest, "chest CT")] {
        let (study, source) = uids(&files[0]);
        let listed = listed_series(&orthanc, &study);
        let rotations = listed
            .iter()
            .filter(|s| s.1 == "OT" && s.2 == "Shapecast shape MIP, HESSIAN, lung-nodules")
            .count();
        assert_eq!(rotations, 1, "{name}: {listed:?}");
        assert!(listed.iter().any(|s| s.0 == source));
        let reports = listed.iter().filter(|s| s.1 == "SR").count();
        assert_eq!(
            reports,
            usize::from(name == "chest CT"),
            "{name}: {listed:?}"
        );
    }

    // A rerun of both shards (a Slurm array, counted from 1) stores nothing new.
    for task in ["1", "2"] {
        let child = spawn_batch(
            &url,
            &[],
            &[
                ("SLURM_ARRAY_TASK_ID", task),
                ("SLURM_ARRAY_TASK_COUNT", "2"),
                ("SLURM_ARRAY_TASK_MIN", "1"),
            ],
        );
        let (ok, again, err) = finish_batch(child);
        assert!(ok, "{err}");
        assert_eq!(count(&again, "done"), 0, "{again}");
        assert_eq!(
            count(&again, "skipped"),
            count(&again, "series_in_shard"),
            "{again}"
        );
    }
    let (chest_study, _) = uids(&chest[0]);
    assert_eq!(
        listed_series(&orthanc, &chest_study)
            .iter()
            .filter(|s| s.1 != "CT")
            .count(),
        2,
        "the rerun stored something"
    );
    // A query that matches nothing: nothing to do.
    let child = spawn_batch(
        &url,
        &["--query", "PatientID=nobody-at-all", "--dry-run"],
        &[],
    );
    let (ok, none, err) = finish_batch(child);
    assert!(ok, "{err}");
    assert_eq!(count(&none, "series_matching"), 0, "{none}");
}

/// tests/io/read_back.py's JSON for a file, or a visible skip where python3 or pydicom is
/// missing (a failure under CI=true: `cargo xtask setup` installs python3-pydicom).
fn pydicom_read_back(path: &Path) -> Option<serde_json::Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/io/read_back.py");
    // Debian's python3, where `cargo xtask setup` installs pydicom (a python3 earlier on PATH,
    // e.g. pyenv's, may lack it).
    let python = ["/usr/bin/python3", "python3"]
        .into_iter()
        .find(|p| !p.starts_with('/') || Path::new(p).exists())
        .unwrap_or("python3");
    let out = Command::new(python).arg(&script).arg(path).output();
    match out {
        Ok(o) if o.status.success() => {
            Some(serde_json::from_slice(&o.stdout).expect("read_back.py's JSON"))
        }
        other => {
            let why = match other {
                Ok(o) => String::from_utf8_lossy(&o.stderr).into_owned(),
                Err(e) => e.to_string(),
            };
            let missing = why.contains("No module named") || !why.contains("Traceback");
            if ci() || !missing {
                panic!("CI=true but pydicom could not read the file back: {why}");
            }
            eprintln!("SKIPPED: pydicom read-back ({why})");
            None
        }
    }
}

#[test]
fn connection_refused_names_the_host() {
    let port = free_port();
    let base = Base::parse(&format!("http://127.0.0.1:{port}/dicom-web")).expect("base");
    let e = Client::new(base, Auth::None)
        .expect("client")
        .resolve("1.2.3", None)
        .expect_err("an error");
    assert!(matches!(e, DicomWebError::Connect { .. }), "{e}");
    let m = e.to_string();
    assert!(
        m.starts_with(&format!("cannot connect to 127.0.0.1:{port}")),
        "{m}"
    );
    let (ok, _, stderr) = shapecast(
        &[
            "info",
            "--dicomweb",
            &format!("http://127.0.0.1:{port}/dicom-web"),
            "--study",
            "1.2.3",
        ],
        &[],
    );
    assert!(
        !ok && stderr.contains(&format!("cannot connect to 127.0.0.1:{port}")),
        "{stderr}"
    );
}

/// A tiny HTTP server on 127.0.0.1 that answers QIDO-RS for one series of two instances and
/// sends the second instance cut short: with a Content-Length it does not honour
/// (`declared_length`), or without one, closing the connection mid-body.
struct CutShortServer {
    port: u16,
    stop: Arc<AtomicBool>,
    hits: Arc<AtomicUsize>,
    thread: Option<std::thread::JoinHandle<()>>,
}

const STUDY: &str = "1.2.826.0.1.3680043.8.498.1";
const SERIES: &str = "1.2.826.0.1.3680043.8.498.1.1";

impl CutShortServer {
    fn start(instance: Vec<u8>, declared_length: bool) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = listener.local_addr().expect("address").port();
        let stop = Arc::new(AtomicBool::new(false));
        let hits = Arc::new(AtomicUsize::new(0));
        let (stop2, hits2) = (stop.clone(), hits.clone());
        let thread = std::thread::spawn(move || {
            for stream in listener.incoming() {
                if stop2.load(Ordering::SeqCst) {
                    return;
                }
                let Ok(stream) = stream else { continue };
                serve(stream, &instance, declared_length, &hits2);
            }
        });
        Self {
            port,
            stop,
            hits,
            thread: Some(thread),
        }
    }
}

impl Drop for CutShortServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = TcpStream::connect(("127.0.0.1", self.port));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn serve(mut stream: TcpStream, instance: &[u8], declared_length: bool, hits: &AtomicUsize) {
    let _ = stream.set_read_timeout(Some(Duration::from_secs(5)));
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") && head.len() < 16384 {
        match stream.read(&mut byte) {
            Ok(1) => head.push(byte[0]),
            _ => return,
        }
    }
    let head = String::from_utf8_lossy(&head);
    let path = head.split_whitespace().nth(1).unwrap_or("").to_owned();
    let json = |v: serde_json::Value| {
        let body = v.to_string();
        format!(
            "HTTP/1.1 200 OK\r\nContent-Type: application/dicom+json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
        .into_bytes()
    };
    let uid = |tag: &str, v: &str| serde_json::json!({ tag: { "vr": "UI", "Value": [v] } });
    let answer: Vec<u8> = if path.starts_with("/dw/studies?") {
        json(serde_json::json!([uid("0020000D", STUDY)]))
    } else if path.ends_with("/series?includefield=00180050") {
        json(serde_json::json!([uid("0020000E", SERIES)]))
    } else if path.ends_with("/instances") {
        json(serde_json::json!([
            uid("00080018", &format!("{SERIES}.1")),
            uid("00080018", &format!("{SERIES}.2"))
        ]))
    } else if path.contains("/instances/") {
        let mut body = b"--CUT\r\nContent-Type: application/dicom\r\n\r\n".to_vec();
        body.extend_from_slice(instance);
        body.extend_from_slice(b"\r\n--CUT--\r\n");
        let full = body.len();
        if path.ends_with(".2") {
            hits.fetch_add(1, Ordering::SeqCst);
            body.truncate(full / 2);
        }
        let length = if declared_length {
            format!("Content-Length: {full}\r\n")
        } else {
            String::new()
        };
        let mut a = format!(
            "HTTP/1.1 200 OK\r\nContent-Type: multipart/related; type=\"application/dicom\"; boundary=CUT\r\n{length}Connection: close\r\n\r\n"
        )
        .into_bytes();
        a.extend_from_slice(&body);
        a
    } else {
        b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_vec()
    };
    let _ = stream.write_all(&answer);
    let _ = stream.flush();
}

#[test]
fn an_instance_cut_short_is_asked_for_again_then_named() {
    let instance =
        std::fs::read(common::test_data("dicom/ct-head-64px/CTHead40.dcm")).expect("bundled DICOM");
    for declared_length in [false, true] {
        let server = CutShortServer::start(instance.clone(), declared_length);
        let base = Base::parse(&format!("http://127.0.0.1:{}/dw", server.port)).expect("base");
        let client = Client::new(base, Auth::None).expect("client");
        let e = shapecast::error::chain(
            &client
                .retrieve(STUDY, SERIES, &mut |_| {})
                .expect_err("an error"),
        );
        assert!(
            e.starts_with(&format!("instance 2 of 2 ({SERIES}.2) failed 2 times")),
            "{e}"
        );
        if declared_length {
            assert!(e.contains("the body broke off"), "{e}");
        } else {
            assert!(e.contains("part 1 was cut short"), "{e}");
        }
        assert_eq!(server.hits.load(Ordering::SeqCst), 2, "asked for twice");
    }
}

/// The viewer (egui_kittest on the test adapter) opening a study from Orthanc as the page's
/// `?dicomweb=` does: the chooser's series, the geometry the file loader gives, the patient line
/// from the header, a link that names the archive and no patient data; with authentication on,
/// the error asks for a token and the dialog opens.
#[test]
fn the_viewer_opens_a_study_and_shows_its_patient() {
    use crate::app_harness;
    use shapecast::app::{AppOptions, DisplayMode, PacsTarget, ShapecastApp, StartWith};
    use shapecast::status::Phase;

    let Some(dir) = common::shared_data("series/mr-prostate-adc-oblique") else {
        return;
    };
    if shapecast::gpu::context::test_context().is_none() {
        return;
    }
    let run = |orthanc: &Orthanc, study: &str, until: &dyn Fn(&ShapecastApp) -> bool| {
        let options = AppOptions {
            start: StartWith::DicomWeb(PacsTarget {
                base: orthanc.url("/dicom-web"),
                study: study.to_owned(),
                series: None,
            }),
            mode: DisplayMode::Intensity,
            compute_on_load: false,
            ..AppOptions::default()
        };
        // The adapter was checked above.
        let mut harness = app_harness::harness(options).expect("a GPU adapter");
        app_harness::run_until(&mut harness, "the study's outcome", 60, until);
        harness.run_steps(2);
        harness
    };

    let files = series_files(&dir);
    let (study, _) = uids(&files[0]);
    let by_files = shapecast::io::load(&files.iter().map(|f| common::input(f)).collect::<Vec<_>>())
        .expect("the file loader");
    let Some(orthanc) = Orthanc::start(false) else {
        return;
    };
    orthanc.upload(&files);
    let harness = run(&orthanc, &study, &|app| {
        app.volume().is_some() || app.status().phase == Phase::Error
    });
    let app = harness.state();
    let v = app.volume().expect("a volume");
    let f = &by_files.volume;
    assert_eq!(
        (v.dims, v.spacing_mm, v.origin_mm, v.direction),
        (f.dims, f.spacing_mm, f.origin_mm, f.direction)
    );
    let patient = by_files.patient.clone().expect("the header's patient");
    let line = app.patient_line().expect("a patient line");
    if let Some(id) = &patient.id {
        assert!(line.contains(&format!("ID {id}")), "{line}");
    }
    let link = app.link();
    assert!(link.contains("dicomweb=http://127.0.0.1:"), "{link}");
    // The dialog's study search (QIDO-RS by patient ID, with a wildcard, and by date).
    let client = Client::new(orthanc.base(), Auth::None).expect("client");
    if let Some(id) = &patient.id {
        let prefix: String = id.chars().take(3).collect();
        let search = shapecast::io::dicomweb::StudySearch {
            patient_id: format!("{prefix}*"),
            ..Default::default()
        };
        let found = client.search_studies(&search).expect("search");
        assert!(found.iter().any(|s| s.study_uid == study), "{found:?}");
    }
    // By patient name (a wildcard) and by modality: the MR study is found as MR, not as CT.
    if let Some(name) = &patient.name {
        let prefix: String = name.chars().take(3).collect();
        let by_name = shapecast::io::dicomweb::StudySearch {
            patient_name: format!("{prefix}*"),
            modality: "MR".to_owned(),
            ..Default::default()
        };
        let found = client.search_studies(&by_name).expect("search");
        assert!(found.iter().any(|s| s.study_uid == study), "{found:?}");
    }
    let as_ct = shapecast::io::dicomweb::StudySearch {
        modality: "CT".to_owned(),
        ..Default::default()
    };
    let found = client.search_studies(&as_ct).expect("search");
    assert!(!found.iter().any(|s| s.study_uid == study), "{found:?}");
    // Paged: the page after the last match is empty.
    let all = client
        .search_studies(&shapecast::io::dicomweb::StudySearch::default())
        .expect("search");
    assert!(all.iter().any(|s| s.study_uid == study), "{all:?}");
    let after = shapecast::io::dicomweb::StudySearch {
        offset: all.len(),
        ..Default::default()
    };
    assert!(client.search_studies(&after).expect("search").is_empty());
    let nobody = shapecast::io::dicomweb::StudySearch {
        study_date: "19000101-19000102".to_owned(),
        ..Default::default()
    };
    assert!(client.search_studies(&nobody).expect("search").is_empty());
    for secret in [&patient.id, &patient.name].into_iter().flatten() {
        assert!(!link.contains(secret.as_str()), "{link}");
        assert!(!app.status().view_json.contains(secret.as_str()));
    }
    // "Store to PACS": the MIP's turn goes into the study as a Secondary Capture series, and
    // an ellipse drawn on the axial pane as a measurement report (SR).
    let mut harness = harness;
    assert!(!harness.state().status().storing);
    harness
        .state_mut()
        .set_tool(shapecast::app::measure::Tool::Ellipse);
    let axial = harness
        .state()
        .status()
        .controls
        .iter()
        .find(|(n, _)| n == "pane:axial")
        .map(|(_, r)| *r)
        .expect("the axial pane");
    let at = |fx: f32, fy: f32| egui::pos2(axial[0] + fx * axial[2], axial[1] + fy * axial[3]);
    app_harness::drag(
        &mut harness,
        egui::PointerButton::Primary,
        at(0.45, 0.45),
        at(0.6, 0.55),
    );
    assert_eq!(harness.state().measurements().len(), 1, "no ellipse drawn");
    app_harness::click_control(&mut harness, "store-pacs");
    assert!(
        harness.state().status().storing,
        "not storing after the click"
    );
    app_harness::run_until(&mut harness, "stored", 400, |app| {
        !app.status().stored.is_empty() || !app.errors().is_empty()
    });
    harness.run_steps(2);
    if let Ok(picture) = harness.render() {
        app_harness::save(&picture, "app_store_pacs.png");
    }
    let app = harness.state();
    assert!(app.errors().is_empty(), "{:?}", app.errors());
    let stored = app.status().stored[0].clone();
    assert_eq!(app.status().stored.len(), 2, "the rotation and the report");
    let report = app.status().stored[1].clone();
    let listed = listed_series(&orthanc, &study);
    let sr = listed
        .iter()
        .find(|s| s.0 == report)
        .unwrap_or_else(|| panic!("{report} not listed: {listed:?}"));
    assert_eq!(
        (sr.1.as_str(), sr.2.as_str()),
        (
            "SR",
            "Shapecast measurements (0 rulers, 1 ellipses, 0 findings)"
        )
    );
    let path = orthanc.dir.join("report.dcm");
    std::fs::write(&path, instance_file(&orthanc, &report)).expect("write the report");
    if let Some(read) = pydicom_read_back(&path) {
        assert_eq!(read["template"], serde_json::json!("1500"), "{read}");
        let groups = read["groups"].as_array().expect("groups");
        assert_eq!(groups.len(), 1, "{read}");
        let names: Vec<&str> = groups[0]["items"]
            .as_array()
            .expect("items")
            .iter()
            .filter_map(|i| i["concept"].as_str())
            .collect();
        // An MR's values have no unit to report: its ellipse reports its area.
        for want in ["Tracking Identifier", "Image Region", "Area"] {
            assert!(names.contains(&want), "{want} missing: {names:?}");
        }
        let region = groups[0]["items"]
            .as_array()
            .and_then(|items| items.iter().find(|i| i["concept"] == "Image Region"))
            .expect("the region");
        assert_eq!(region["graphic_type"], "ELLIPSE", "{region}");
        assert_eq!(region["points"].as_array().map_or(0, Vec::len), 12);
    }
    let sc = listed
        .iter()
        .find(|s| s.0 == stored)
        .unwrap_or_else(|| panic!("{stored} not listed: {listed:?}"));
    assert_eq!((sc.1.as_str(), sc.2.as_str()), ("OT", "Shapecast MIP"));
    let file = instance_file(&orthanc, &stored);
    let obj = dicom_object::from_reader(&file[128..]).expect("a DICOM file");
    let frames = obj
        .element_by_name("NumberOfFrames")
        .ok()
        .and_then(|e| e.to_int::<u32>().ok());
    assert_eq!(frames, Some(shapecast::app::MOVIE_FRAMES));
    drop(harness);

    let Some(locked) = Orthanc::start(true) else {
        return;
    };
    locked.upload(&files);
    let harness = run(&locked, &study, &|app| app.status().phase == Phase::Error);
    let app = harness.state();
    let error = app.errors().last().cloned().unwrap_or_default();
    assert!(error.contains("401") && error.contains("token"), "{error}");
    let (dialog, message) = app.pacs_dialog();
    assert!(dialog && message.is_some_and(|m| m.contains("Paste a bearer token")));
    assert!(app.volume().is_none());
}
