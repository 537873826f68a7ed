//! flexmpc's integration tests, one binary: the CLI end to end, its failure modes, every
//! shipped and malformed scene, the default controller, the
//! guide's command blocks, internal errors, reproducible outputs, the report in headless
//! Chromium and the ParaView export.

mod cli;
mod cli_breaks;
mod defaults;
mod guide_commands;
mod internal_error;
mod report_chromium;
mod reproducible;
mod scenes;
mod vtk_export;
