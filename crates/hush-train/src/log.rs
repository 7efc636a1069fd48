//! The training logs as text: `loss.csv` (a row per step) and `metrics.csv` (a row per epoch). Written with
//! a header of named columns and read back by those names, so a reader never depends on column order and a
//! file with extra or missing optional columns still reads.

use crate::{EpochRow, LossRow};

/// The columns of `loss.csv`.
pub const LOSS_COLUMNS: [&str; 5] = ["step", "epoch", "loss", "lr", "seconds"];
/// The columns of `metrics.csv`.
pub const METRICS_COLUMNS: [&str; 8] =
    ["epoch", "step", "train_loss", "test_loss", "lr", "seconds", "loader_share", "best"];

/// `loss.csv` of `log`.
pub fn loss_csv(log: &[LossRow]) -> String {
    let mut csv = LOSS_COLUMNS.join(",") + "\n";
    for r in log {
        csv.push_str(&format!("{},{},{},{},{:.3}\n", r.step, r.epoch, r.loss, r.lr, r.seconds));
    }
    csv
}

/// `metrics.csv` of `rows`; an epoch without a test loss leaves its cell empty.
pub fn metrics_csv(rows: &[EpochRow]) -> String {
    let mut csv = METRICS_COLUMNS.join(",") + "\n";
    for r in rows {
        let test = r.test_loss.map(|t| t.to_string()).unwrap_or_default();
        csv.push_str(&format!(
            "{},{},{},{test},{},{:.3},{:.4},{}\n",
            r.epoch, r.step, r.train_loss, r.lr, r.seconds, r.loader_share, r.best
        ));
    }
    csv
}

/// The rows of a CSV text as a lookup by column name; rows that do not parse are skipped by the callers.
struct Table<'a> {
    header: Vec<&'a str>,
    rows: Vec<Vec<&'a str>>,
}

impl<'a> Table<'a> {
    fn parse(text: &'a str) -> Self {
        let mut lines = text.lines();
        let header = lines.next().unwrap_or_default().split(',').map(str::trim).collect();
        Table { header, rows: lines.map(|l| l.split(',').map(str::trim).collect()).collect() }
    }

    /// The cell of column `name` in `row`, if the column exists and the row reaches it.
    fn cell(&self, row: &[&'a str], name: &str) -> Option<&'a str> {
        row.get(self.header.iter().position(|h| *h == name)?).copied()
    }

    fn number<T: std::str::FromStr>(&self, row: &[&'a str], name: &str) -> Option<T> {
        self.cell(row, name)?.parse().ok()
    }
}

/// The rows of a `loss.csv` (rows missing a column are skipped).
pub fn parse_loss_csv(text: &str) -> Vec<LossRow> {
    let t = Table::parse(text);
    t.rows
        .iter()
        .filter_map(|r| {
            Some(LossRow {
                step: t.number(r, "step")?,
                epoch: t.number(r, "epoch")?,
                loss: t.number(r, "loss")?,
                lr: t.number(r, "lr")?,
                seconds: t.number(r, "seconds")?,
            })
        })
        .collect()
}

/// The rows of a `metrics.csv`: `epoch`, `step`, `train_loss`, `lr` and `seconds` are required; an empty or
/// missing `test_loss` is none, a missing `loader_share` 0 and `best` false.
pub fn parse_metrics_csv(text: &str) -> Vec<EpochRow> {
    let t = Table::parse(text);
    t.rows
        .iter()
        .filter_map(|r| {
            Some(EpochRow {
                epoch: t.number(r, "epoch")?,
                step: t.number(r, "step")?,
                train_loss: t.number(r, "train_loss")?,
                test_loss: t.number(r, "test_loss"),
                lr: t.number(r, "lr")?,
                seconds: t.number(r, "seconds")?,
                loader_share: t.number(r, "loader_share").unwrap_or(0.0),
                best: t.number(r, "best").unwrap_or(false),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both logs read back what was written, and a reader finds the columns by name: reordered or extra
    /// columns read the same, a row missing a required cell is skipped.
    #[test]
    fn logs_read_back_by_column_name() {
        let log = vec![LossRow { step: 1, epoch: 1, loss: 0.5, lr: 1e-3, seconds: 0.25 }];
        assert_eq!(parse_loss_csv(&loss_csv(&log)), log);
        let rows = vec![
            EpochRow {
                epoch: 1,
                step: 2,
                train_loss: 0.4,
                test_loss: None,
                lr: 1e-3,
                seconds: 1.5,
                loader_share: 0.125,
                best: false,
            },
            EpochRow {
                epoch: 2,
                step: 4,
                train_loss: 0.3,
                test_loss: Some(0.35),
                lr: 1e-3,
                seconds: 3.0,
                loader_share: 0.0625,
                best: true,
            },
        ];
        assert_eq!(parse_metrics_csv(&metrics_csv(&rows)), rows);
        let reordered = "extra,seconds,lr,loss,epoch,step\nx,0.25,0.001,0.5,1,1\n,,,,,2\n";
        assert_eq!(parse_loss_csv(reordered), log);
    }
}
