//! Measurement tables: a real population given as a CSV of features in mm, one row per
//! patient (what trial sponsors and SIMCor's R tool exchange), as a reference without
//! surfaces.
//!
//! Rules, each a [`InputError`] naming the column or row:
//! * comma- or semicolon-separated (R's `write.csv2`), RFC 4180 quoting, a header row;
//! * a column is one of our feature names or SIMCor's (see [`super::features`]); an
//!   identifier column (`id`, `patient`, `patient_id`, `case`, `case_id`, `subject`,
//!   `name`, or R's unnamed row-name column) labels rows; SIMCor's unmeasured features are
//!   kept aside as not compared; any other column is refused;
//! * a unit may follow the name in brackets or parentheses (`D_an [mm]`, `area_mm2 (mm2)`)
//!   and must be mm for lengths, mm² for areas, mm³ for volumes;
//! * values are finite numbers ≥ 0 (a decimal comma is accepted in a semicolon table);
//!   an empty cell, `NA` or `NaN` is a missing value; at least two rows.

use super::InputError;
use super::features::{Feature, FeatureValues, SIMCOR_UNMEASURED};
use super::population::{Member, Population};

/// Identifier column names (lower case).
const ID_COLUMNS: [&str; 7] = [
    "id",
    "patient",
    "patient_id",
    "case",
    "case_id",
    "subject",
    "name",
];
/// Cells read as a missing value.
const MISSING: [&str; 4] = ["", "na", "nan", "null"];

/// A parsed measurement table.
#[derive(Debug, Clone)]
pub struct MeasurementTable {
    /// The rows as a population without surfaces.
    pub population: Population,
    /// The compared features, in column order.
    pub features: Vec<Feature>,
    /// Columns accepted but not compared, with the reason.
    pub ignored: Vec<(String, String)>,
}

/// What a header cell is.
enum Column {
    Id,
    Feature(Feature),
    Ignored,
}

/// Parses `text` as a measurement table named `label`.
pub fn parse_table(label: &str, text: &str) -> Result<MeasurementTable, InputError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header = lines
        .next()
        .ok_or_else(|| InputError::new("table", "empty", "the table has no header row"))?;
    let delimiter = if header.contains(';') && !header.contains(',') {
        ';'
    } else {
        ','
    };
    let names = split_row(header, delimiter);
    let mut columns = Vec::with_capacity(names.len());
    let mut ignored = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let column = classify(name, i)?;
        if let Column::Ignored = column {
            let why = "a SIMCor feature aortagen does not measure (outflow tract or valve)";
            ignored.push((name.clone(), why.to_owned()));
        }
        columns.push(column);
    }
    let features: Vec<Feature> = columns
        .iter()
        .filter_map(|c| match c {
            Column::Feature(f) => Some(*f),
            _ => None,
        })
        .collect();
    if features.is_empty() {
        let msg = format!(
            "no column names a measurement; expected {}",
            Feature::names()
        );
        return Err(InputError::new("columns", "no-measurement", msg));
    }
    if let Some(f) = (1..features.len())
        .find_map(|i| features[..i].contains(&features[i]).then_some(features[i]))
    {
        let msg = format!(
            "{} is given twice (directly or by its SIMCor name)",
            f.name()
        );
        return Err(InputError::new(
            format!("columns[{}]", f.name()),
            "distinct",
            msg,
        ));
    }
    let mut members = Vec::new();
    for (row, line) in lines.enumerate() {
        members.push(read_row(row, line, delimiter, &names, &columns)?);
    }
    if members.len() < 2 {
        let msg = format!("a reference needs at least 2 rows, got {}", members.len());
        return Err(InputError::new("rows", "too-few", msg));
    }
    Ok(MeasurementTable {
        population: Population {
            label: label.to_owned(),
            members,
        },
        features,
        ignored,
    })
}

fn classify(header: &str, index: usize) -> Result<Column, InputError> {
    let (name, unit) = split_unit(header);
    let field = || format!("columns[{header}]");
    if name.is_empty() && index == 0 {
        return Ok(Column::Id);
    }
    if ID_COLUMNS.contains(&name.to_ascii_lowercase().as_str()) {
        return Ok(Column::Id);
    }
    if SIMCOR_UNMEASURED.contains(&name) {
        return Ok(Column::Ignored);
    }
    let Some(feature) = Feature::parse(name) else {
        let msg = format!(
            "{name:?} is not a measurement; expected {}",
            Feature::names()
        );
        return Err(InputError::new(field(), "unknown-column", msg));
    };
    if let Some(unit) = unit
        && !unit_matches(unit, feature.dimension())
    {
        let msg = format!(
            "{} must be given in {}, the column says {unit:?}; convert the values",
            feature.name(),
            feature.unit()
        );
        return Err(InputError::new(field(), "units", msg));
    }
    Ok(Column::Feature(feature))
}

/// `D_an [mm]` → (`D_an`, Some(`mm`)); `D_an` → (`D_an`, None).
fn split_unit(header: &str) -> (&str, Option<&str>) {
    let h = header.trim();
    for (open, close) in [('[', ']'), ('(', ')')] {
        if let Some(stripped) = h.strip_suffix(close)
            && let Some((name, unit)) = stripped.rsplit_once(open)
        {
            return (name.trim(), Some(unit.trim()));
        }
    }
    (h, None)
}

fn unit_matches(unit: &str, dimension: u32) -> bool {
    let u = unit.to_ascii_lowercase().replace(' ', "");
    match dimension {
        1 => u == "mm",
        2 => ["mm2", "mm^2", "mm²", "sqmm"].contains(&u.as_str()),
        _ => ["mm3", "mm^3", "mm³"].contains(&u.as_str()),
    }
}

fn read_row(
    row: usize,
    line: &str,
    delimiter: char,
    names: &[String],
    columns: &[Column],
) -> Result<Member, InputError> {
    let cells = split_row(line, delimiter);
    if cells.len() != columns.len() {
        let msg = format!("has {} cells, the header {}", cells.len(), columns.len());
        return Err(InputError::new(format!("rows[{row}]"), "cells", msg));
    }
    let mut name = format!("row {row}");
    let mut values = FeatureValues::default();
    for ((cell, column), header) in cells.iter().zip(columns).zip(names) {
        match column {
            Column::Id => name.clone_from(cell),
            Column::Ignored => {}
            Column::Feature(f) => {
                if let Some(v) = parse_value(cell, delimiter)
                    .map_err(|msg| InputError::new(format!("rows[{row}].{header}"), "value", msg))?
                {
                    values.0.insert(*f, v);
                }
            }
        }
    }
    Ok(Member {
        name,
        surface_mm: None,
        features: values,
    })
}

fn parse_value(cell: &str, delimiter: char) -> Result<Option<f64>, String> {
    let c = cell.trim();
    if MISSING.contains(&c.to_ascii_lowercase().as_str()) {
        return Ok(None);
    }
    let text = if delimiter == ';' {
        c.replace(',', ".")
    } else {
        c.to_owned()
    };
    let v: f64 = text.parse().map_err(|_| format!("{c:?} is not a number"))?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(format!("{c} must be a finite number ≥ 0"));
    }
    Ok(Some(v))
}

/// The cells of one line: RFC 4180 quoting (`"a,b"`, `""` for a quote), trimmed.
fn split_row(line: &str, delimiter: char) -> Vec<String> {
    let mut cells = Vec::new();
    let mut cell = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cell.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (d, false) if d == delimiter => cells.push(std::mem::take(&mut cell).trim().to_owned()),
            (other, _) => cell.push(other),
        }
    }
    cells.push(cell.trim().to_owned());
    cells
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anatomy::measurement::Measurement;

    #[test]
    fn a_simcor_table_maps_its_columns_and_keeps_the_unmeasured_aside() {
        let csv = "\"\",\"D_lvot\",\"D_an\",\"D_sinus\",\"D_stj\",\"AVA\",\"H_sinus\"\n\
                   \"1\",21.0,23.5,31.2,27.0,3.1,20.4\n\
                   \"2\",22.0,NA,33.0,28.5,3.4,21.9\n";
        let t = parse_table("trial", csv).unwrap();
        let annulus = Feature::Anatomy(Measurement::Annulus);
        assert_eq!(t.features.len(), 4);
        assert_eq!(t.features[0], annulus);
        assert_eq!(
            t.ignored
                .iter()
                .map(|(c, _)| c.as_str())
                .collect::<Vec<_>>(),
            ["D_lvot", "AVA"]
        );
        assert_eq!(t.population.values(annulus), [23.5]);
        assert_eq!(t.population.members[1].name, "2");
        assert_eq!(
            t.population
                .values(Feature::Anatomy(Measurement::SinusHeight)),
            [20.4, 21.9]
        );
        assert!(!t.population.has_surfaces());
    }

    #[test]
    fn semicolon_tables_with_decimal_commas_and_units_in_headers_are_read() {
        let csv = "patient;annulus_mm [mm];area_mm2 (mm²)\na;23,5;1200\nb;24;1300,5\n";
        let t = parse_table("t", csv).unwrap();
        assert_eq!(
            t.population.values(Feature::Anatomy(Measurement::Annulus)),
            [23.5, 24.0]
        );
        assert_eq!(t.population.values(Feature::Area), [1200.0, 1300.5]);
        assert_eq!(t.population.members[0].name, "a");
    }

    #[test]
    fn every_broken_rule_names_the_column_or_row() {
        let cases = [
            (
                "id,D_an,colour\n1,2,3\n2,3,4\n",
                "columns[colour]",
                "unknown-column",
            ),
            ("id,D_an [cm]\n1,2\n2,3\n", "columns[D_an [cm]]", "units"),
            (
                "id,volume_mm3 (mm2)\n1,2\n2,3\n",
                "columns[volume_mm3 (mm2)]",
                "units",
            ),
            ("id,D_an\n1,2\n", "rows", "too-few"),
            ("id,D_an\n1,2\n2,x\n", "rows[1].D_an", "value"),
            ("id,D_an\n1,-2\n2,3\n", "rows[0].D_an", "value"),
            ("id,D_an\n1,2,3\n2,3\n", "rows[0]", "cells"),
            (
                "id,D_an,annulus_mm\n1,2,2\n2,3,3\n",
                "columns[annulus_mm]",
                "distinct",
            ),
            ("id,D_lvot\n1,2\n2,3\n", "columns", "no-measurement"),
            ("", "table", "empty"),
        ];
        for (csv, field, rule) in cases {
            let err = parse_table("t", csv).unwrap_err();
            assert_eq!(
                (err.field.as_str(), err.rule),
                (field, rule),
                "{csv:?}: {err}"
            );
        }
    }

    #[test]
    fn quoted_cells_keep_delimiters_and_quotes() {
        assert_eq!(
            split_row("\"a,b\",\"say \"\"hi\"\"\", c ", ','),
            ["a,b", "say \"hi\"", "c"]
        );
    }
}
