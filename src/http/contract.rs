//! The rules the server checks, written into the OpenAPI document from the constants the
//! checks themselves use: page sizes, formats, units, plot names, the cohort request's
//! bounds, the sampler's and the simulation mesh's. utoipa's attributes take literal
//! numbers only, so this pass fills them in after the document is generated; a bound
//! changed in the code changes the contract with it, and a rule naming a parameter or a
//! property the document does not have stops the document from being built.

use utoipa::Number;
use utoipa::openapi::schema::{ArrayItems, Object, Schema, Type};
use utoipa::openapi::{OpenApi, RefOr};

use crate::anatomy::measurement::Measurement;
use crate::cohort::RESOLUTION_RANGE;
use crate::cohort::request::{MIN_CONVEX_ARITY, MIN_COUNT};
use crate::cohort::sampler::{MAX_COMPONENTS, MIN_MIXTURE_MODES};
use crate::cohort::targets::MAX_CANDIDATES;
use crate::db::states::JobStatus;
use crate::sdf::training::fit::MAX_FIT_ITERATIONS;
use crate::simulation::Variant;
use crate::simulation::opening::OPTION_RANGES_MM;
use crate::simulation::remesh::TARGET_RANGE_MM;
use crate::simulation::request::MAX_EXTENSION_DIAMETERS;

/// What the server accepts for one value.
#[derive(Debug, Clone, PartialEq)]
pub enum Rule {
    /// An integer within `min..=max` (an absent end is open).
    Integer {
        /// Smallest accepted value.
        min: Option<i64>,
        /// Largest accepted value.
        max: Option<i64>,
    },
    /// A finite number from `min` (itself refused when `exclusive_min`) to `max`.
    Number {
        /// Lower bound.
        min: f64,
        /// Whether `min` itself is refused.
        exclusive_min: bool,
        /// Largest accepted value.
        max: Option<f64>,
    },
    /// One of these strings.
    OneOf(Vec<&'static str>),
}

impl Rule {
    fn at_least(min: i64) -> Self {
        Self::Integer {
            min: Some(min),
            max: None,
        }
    }

    fn between(min: i64, max: i64) -> Self {
        Self::Integer {
            min: Some(min),
            max: Some(max),
        }
    }

    fn non_negative() -> Self {
        Self::Number {
            min: 0.0,
            exclusive_min: false,
            max: None,
        }
    }

    fn positive(max: Option<f64>) -> Self {
        Self::Number {
            min: 0.0,
            exclusive_min: true,
            max,
        }
    }

    fn within(min: f64, max: f64) -> Self {
        Self::Number {
            min,
            exclusive_min: false,
            max: Some(max),
        }
    }

    /// Writes the rule into a parameter's or property's schema.
    fn apply(&self, schema: &mut Schema) {
        match (self, schema) {
            (Self::OneOf(values), Schema::Object(o)) => {
                o.enum_values = Some(values.iter().map(|v| (*v).into()).collect());
            }
            (Self::Integer { min, max }, Schema::Object(o)) => {
                o.minimum = min.map(|m| Number::Int(m as isize));
                o.maximum = max.map(|m| Number::Int(m as isize));
            }
            (
                Self::Number {
                    min,
                    exclusive_min,
                    max,
                },
                Schema::Object(o),
            ) => {
                let min = Some(Number::Float(*min));
                (o.minimum, o.exclusive_minimum) = match exclusive_min {
                    true => (None, min),
                    false => (min, None),
                };
                o.maximum = max.map(Number::Float);
            }
            (rule, Schema::Array(a)) => match &mut a.items {
                ArrayItems::RefOrSchema(items) => match items.as_mut() {
                    RefOr::T(item) => rule.apply(item),
                    RefOr::Ref(r) => panic!("array items {} are a reference", r.ref_location),
                },
                ArrayItems::False => panic!("an array without items"),
            },
            (rule, _) => panic!("cannot write {rule:?} into a schema of another kind"),
        }
    }
}

/// Query and path parameters: (path, parameter, rule). Each must name a parameter of at
/// least one operation on the path.
pub fn parameter_rules() -> Vec<(&'static str, &'static str, Rule)> {
    let page = crate::http::cohorts::PAGE_LIMIT;
    let limit = || Rule::between(*page.start(), *page.end());
    let statuses = JobStatus::ALL.iter().map(|s| s.as_str()).collect();
    let mut rules = vec![
        ("/v1/cohorts", "limit", limit()),
        ("/v1/cohorts", "offset", Rule::at_least(0)),
        ("/v1/cohorts", "status", Rule::OneOf(statuses)),
        ("/v1/cohorts/{id}/shapes", "limit", limit()),
        ("/v1/cohorts/{id}/shapes", "offset", Rule::at_least(0)),
        (
            "/v1/cohorts/{id}/metrics",
            "format",
            Rule::OneOf(crate::http::cohorts::metrics::METRICS_FORMATS.to_vec()),
        ),
        (
            "/v1/shapes/{id}/mesh",
            "units",
            Rule::OneOf(crate::http::shapes::UNITS.to_vec()),
        ),
        // Cohort archives are written in mm only.
        (
            "/v1/cohorts/{id}/meshes.zip",
            "units",
            Rule::OneOf(vec![crate::http::shapes::UNITS[0]]),
        ),
        // The closed surface has no face table.
        (
            "/v1/shapes/{id}/faces",
            "openings",
            Rule::OneOf(Variant::ALL.iter().map(|v| v.name()).collect()),
        ),
        (
            "/v1/models/{id}/plots/{plot}",
            "plot",
            Rule::OneOf(crate::http::reports::MODEL_PLOTS.to_vec()),
        ),
        (
            "/v1/cohorts/{id}/plots/{plot}",
            "plot",
            Rule::OneOf(crate::http::reports::COHORT_PLOTS.to_vec()),
        ),
        (
            "/v1/models/{id}/fit",
            "iterations",
            Rule::between(1, MAX_FIT_ITERATIONS as i64),
        ),
        (
            "/v1/models",
            "epochs",
            Rule::between(1, crate::http::model_upload::MAX_EPOCHS as i64),
        ),
        // The most depends on the number of meshes uploaded (two must remain).
        (
            "/v1/models",
            "holdout",
            Rule::at_least(crate::http::model_upload::MIN_HOLDOUT as i64),
        ),
    ];
    let simulation_paths = [
        "/v1/shapes/{id}/mesh",
        "/v1/shapes/{id}/faces",
        "/v1/cohorts/{id}/meshes.zip",
    ];
    for path in simulation_paths {
        let (lo, hi) = TARGET_RANGE_MM;
        rules.push((path, "remesh_mm", Rule::within(lo, hi)));
        let extension = Rule::within(0.0, MAX_EXTENSION_DIAMETERS);
        rules.push((path, "extension_diameters", extension));
        for &(name, lo, hi) in OPTION_RANGES_MM.iter() {
            // The ring spacing is the pipeline's own setting, not a parameter.
            if name != "ring_spacing_mm" {
                rules.push((path, name, Rule::within(lo, hi)));
            }
        }
    }
    rules
}

/// Properties of component schemas: (schema, property, rule); an array property's rule
/// holds for each item.
pub fn property_rules() -> Vec<(&'static str, &'static str, Rule)> {
    let resolution = Rule::between(
        *RESOLUTION_RANGE.start() as i64,
        *RESOLUTION_RANGE.end() as i64,
    );
    vec![
        ("CreateCohort", "count", Rule::at_least(MIN_COUNT)),
        ("CreateCohort", "arity", Rule::at_least(MIN_CONVEX_ARITY)),
        ("CreateCohort", "weights", Rule::within(0.0, 1.0)),
        ("CreateCohort", "resolution", resolution),
        ("CreateCohort", "latent_noise", Rule::non_negative()),
        ("CreateCohort", "min_novelty", Rule::non_negative()),
        (
            "CreateCohort",
            "max_candidates",
            Rule::between(1, i64::from(MAX_CANDIDATES)),
        ),
        ("SamplerFields", "truncation", Rule::positive(None)),
        ("SamplerFields", "sigma_scale", Rule::positive(None)),
        ("SamplerFields", "shrinkage", Rule::within(0.0, 1.0)),
        ("SamplerFields", "variance_share", Rule::positive(Some(1.0))),
        (
            "SamplerFields",
            "components",
            Rule::between(1, MAX_COMPONENTS),
        ),
        (
            "SamplerFields",
            "max_components",
            Rule::between(1, MAX_COMPONENTS),
        ),
        (
            "SamplerFields",
            "mixture_modes",
            Rule::at_least(MIN_MIXTURE_MODES),
        ),
        ("TargetRange", "min", Rule::non_negative()),
        ("TargetRange", "max", Rule::non_negative()),
        (
            "FitUpload",
            "iterations",
            Rule::between(1, MAX_FIT_ITERATIONS as i64),
        ),
        (
            "ModelUpload",
            "epochs",
            Rule::between(1, crate::http::model_upload::MAX_EPOCHS as i64),
        ),
        (
            "ModelUpload",
            "holdout",
            Rule::at_least(crate::http::model_upload::MIN_HOLDOUT as i64),
        ),
    ]
}

/// The measurement names a cohort's `targets` may use, as the names of its properties.
fn target_names() -> Schema {
    let names = Measurement::ALL.iter().map(|m| m.name()).collect();
    let mut schema = Schema::Object(Object::with_type(Type::String));
    Rule::OneOf(names).apply(&mut schema);
    schema
}

/// Writes every rule into `doc`.
pub fn write_rules(doc: &mut OpenApi) {
    for (path, name, rule) in parameter_rules() {
        let item = doc
            .paths
            .paths
            .get_mut(path)
            .unwrap_or_else(|| panic!("no path {path}"));
        let operations = [
            &mut item.get,
            &mut item.post,
            &mut item.put,
            &mut item.patch,
            &mut item.delete,
        ];
        let mut found = 0;
        for op in operations.into_iter().flatten() {
            for p in op.parameters.iter_mut().flatten() {
                let RefOr::T(p) = p else { continue };
                if p.name != name {
                    continue;
                }
                match p.schema.as_mut() {
                    Some(RefOr::T(schema)) => rule.apply(schema),
                    // A shared enumeration narrowed for this operation.
                    Some(shared @ RefOr::Ref(_)) => {
                        let mut schema = Schema::Object(Object::with_type(Type::String));
                        rule.apply(&mut schema);
                        *shared = RefOr::T(schema);
                    }
                    None => panic!("parameter {name} of {path} has no schema"),
                }
                found += 1;
            }
        }
        assert!(found > 0, "no parameter {name} on {path}");
    }
    let schemas = &mut doc
        .components
        .as_mut()
        .expect("the document has components")
        .schemas;
    for (schema, property, rule) in property_rules() {
        let Some(RefOr::T(Schema::Object(object))) = schemas.get_mut(schema) else {
            panic!("no object schema {schema}");
        };
        match object.properties.get_mut(property) {
            Some(RefOr::T(s)) => rule.apply(s),
            _ => panic!("no inline property {schema}.{property}"),
        }
    }
    let Some(RefOr::T(Schema::Object(cohort))) = schemas.get_mut("CreateCohort") else {
        panic!("no object schema CreateCohort");
    };
    match cohort.properties.get_mut("targets") {
        Some(RefOr::T(Schema::Object(targets))) => {
            targets.property_names = Some(Box::new(target_names()));
        }
        _ => panic!("CreateCohort.targets is not an inline object"),
    }
}
