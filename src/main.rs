//! The `halftrace` command line: parse and run ([`halftrace::commands`]),
//! report an error with its causes.

#![deny(unsafe_code)]

use clap::Parser;
use halftrace::commands::Cli;

fn main() {
    // A bad flag or value exits 1 like every other error (clap's own code is 2); help and
    // version print and exit 0.
    let cli = Cli::try_parse().unwrap_or_else(|e| {
        let code = if e.use_stderr() { 1 } else { 0 };
        let _ = e.print();
        std::process::exit(code)
    });
    // A run stopped by SIGTERM or Ctrl-C leaves no lock on its output folder.
    halftrace::outdir::release_on_signal();
    let r = cli.cmd.run();
    if let Err(e) = r {
        // stdout closed by its reader (`halftrace devices | head`): the reader has what it
        // wanted; end quietly, as other tools do.
        if e.chain()
            .any(|c| c.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe))
        {
            std::process::exit(0);
        }
        // The context chain, each cause once: an error whose message already quotes its
        // source (an OS or gzip error) does not print it again.
        let mut msg = e.to_string();
        for c in e.chain().skip(1) {
            let t = c.to_string();
            if !msg.contains(&t) {
                msg += ": ";
                msg += &t;
            }
        }
        eprintln!("error: {msg}");
        std::process::exit(1);
    }
}
