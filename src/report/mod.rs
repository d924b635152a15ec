//! Results and their report: rows with a typed identity and status, stored as CSV and JSON
//! as they come ([`rows`]); the tables computed from them ([`tables`]); `report.md`
//! ([`markdown`]) and its plots ([`plots`]); and the merge of several result folders into one
//! report ([`merge`]). Pure functions of the rows: nothing here traces.

pub mod csvx;
pub mod estimate;
pub mod isa;
pub mod key;
pub mod markdown;
pub mod memory;
pub mod merge;
pub mod plots;
pub mod rows;
pub mod tables;

pub use key::{f32_peer, Keyed, What};
pub use markdown::render;
pub use rows::{is_image, is_output, read_rows, sorted, write_rows, Row, RowId, Status, Writer, OUTPUTS};
