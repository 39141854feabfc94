//! `kpl keys`: make the keys of a deployment: a certificate authority, a certificate and key per
//! host of the spec's deploy section, and the secret of the messages' authentication tags
//! (`kpl_zenoh::credentials`; docs/streams.md, "Keys").

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args as ClapArgs;

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl keys specs/zenoh/endless.kpl --out keys/endless\n  kpl run specs/zenoh/endless.kpl --host producer --clock wall --for 3s --keys keys/endless\n\nFiles that exist are kept: after adding a host to the spec, run it again to add that host's\ncertificate, signed by the same authority. Each host needs ca.pem, secret, HOST.pem and HOST.key;\nca.key is needed only to add hosts (keep it apart).\nExit status: 0 done, 1 the spec has errors or no deploy section, 2 I/O errors."
)]
pub struct Args {
    /// The spec whose hosts get keys.
    pub spec: PathBuf,
    /// The keys folder to write (created if needed).
    #[arg(long)]
    pub out: PathBuf,
    /// The deployment's name, written into the authority's certificate (default: the spec's
    /// `deploy NAME`, else `default`).
    #[arg(long)]
    pub deployment: Option<String>,
}

pub fn run(args: Args) -> ExitCode {
    let spec = match super::check::load_checked(&args.spec) {
        Ok(spec) => spec,
        Err(code) => return code,
    };
    let Some(deploy) = &spec.deploy else {
        eprintln!(
            "error: {} has no deploy section: keys are for the hosts of a deployment",
            args.spec.display()
        );
        return ExitCode::from(1);
    };
    let deployment = args
        .deployment
        .clone()
        .or_else(|| deploy.name.clone())
        .unwrap_or_else(|| kpl_runtime::run::DEFAULT_DEPLOYMENT.to_string());
    let hosts: Vec<String> = deploy.hosts.iter().map(|h| h.name.clone()).collect();
    match kpl_zenoh::credentials::make(&args.out, &deployment, &hosts) {
        Ok(made) => {
            for path in &made.written {
                eprintln!("wrote {}", path.display());
            }
            if !made.kept.is_empty() {
                eprintln!("kept {} file(s) that existed", made.kept.len());
            }
            eprintln!(
                "keys of deployment `{deployment}` for host(s) {} in {}",
                hosts.join(", "),
                args.out.display()
            );
            ExitCode::SUCCESS
        }
        Err(err) => {
            eprintln!("error: {err}");
            ExitCode::from(2)
        }
    }
}
