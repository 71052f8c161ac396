//! The database file format against corrupt content: `from_arrays` refuses it with
//! an error and never panics (no wrapped-around counts, no capacity overflow).
use super::*;
use crate::body::{BodyModel, NUM_JOINTS, NUM_PARAMS};
use proptest::prelude::*;

/// A well-formed database of `count` samples per template (no rendering needed).
fn arrays(count: i64) -> TemplateArrays {
    let model = BodyModel::default();
    let config = TemplateConfig::default();
    let t = NUM_TEMPLATES;
    let s = t * count as usize;
    let dim = config.descriptor.dim();
    TemplateArrays {
        format_version: FORMAT_VERSION,
        hash: TemplateDatabase::settings_hash(&model, &config),
        shape: model.shape.to_vec().to_vec(),
        config: config_to_vec(&config).to_vec(),
        poses: vec![0.0; t * NUM_PARAMS],
        views: (0..t as i64).map(|i| i % NUM_VIEWS as i64).collect(),
        joints: vec![0.5; t * NUM_JOINTS * 3],
        centroids: vec![0.0; t * 3],
        sizes: vec![1.0; t],
        counts: vec![count; t],
        context_scale: vec![1.0; t],
        context_centroid: vec![0.0; t * 2],
        context_points: vec![100; t],
        sample_pixels: vec![1.0; 2 * s],
        sample_positions: vec![0.1; 2 * s],
        descriptors: vec![0.01; dim * s],
    }
}

#[test]
fn well_formed_arrays_load_and_wrapped_counts_do_not() {
    assert!(TemplateDatabase::from_arrays(&arrays(2), None, "f").is_ok());
    // Counts that sum past i64 to the right total once wrapped around:
    // 2 (i64::MAX) + 8 + 765 · 2 = 2 · 768 (mod 2^64).
    let mut a = arrays(2);
    a.counts[0] = i64::MAX;
    a.counts[1] = i64::MAX;
    a.counts[2] = 8;
    let r = TemplateDatabase::from_arrays(&a, None, "f");
    assert!(matches!(r, Err(crate::Error::File { .. })), "{r:?}");
}

/// Which array a case corrupts, and how.
#[derive(Debug, Clone)]
enum Corruption {
    Count {
        index: usize,
        value: i64,
    },
    Truncate {
        field: usize,
        keep: usize,
    },
    Value {
        field: usize,
        index: usize,
        value: f64,
    },
    View {
        index: usize,
        value: i64,
    },
    Config {
        index: usize,
        value: f64,
    },
}

fn corruption() -> impl Strategy<Value = Corruption> {
    let big = prop_oneof![
        any::<i64>(),
        Just(i64::MAX),
        Just(i64::MIN),
        -3i64..5,
        Just(i64::MAX / 2 + 1)
    ];
    let value = prop_oneof![
        any::<f64>(),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(1e300),
        Just(-1.0)
    ];
    prop_oneof![
        (0usize..NUM_TEMPLATES, big.clone())
            .prop_map(|(index, value)| Corruption::Count { index, value }),
        (0usize..6, any::<usize>()).prop_map(|(field, keep)| Corruption::Truncate { field, keep }),
        (0usize..4, any::<usize>(), value.clone()).prop_map(|(field, index, value)| {
            Corruption::Value {
                field,
                index,
                value,
            }
        }),
        (0usize..NUM_TEMPLATES, big).prop_map(|(index, value)| Corruption::View { index, value }),
        (0usize..CONFIG_VALUES, value)
            .prop_map(|(index, value)| Corruption::Config { index, value }),
    ]
}

fn apply(a: &mut TemplateArrays, c: &Corruption) {
    fn cut<T>(v: &mut Vec<T>, keep: usize) {
        let n = v.len();
        v.truncate(keep % (n + 1));
    }
    fn set<T>(v: &mut [T], index: usize, value: T) {
        if !v.is_empty() {
            let n = v.len();
            v[index % n] = value;
        }
    }
    match *c {
        Corruption::Count { index, value } => set(&mut a.counts, index, value),
        Corruption::Truncate { field, keep } => match field {
            0 => cut(&mut a.poses, keep),
            1 => cut(&mut a.counts, keep),
            2 => cut(&mut a.descriptors, keep),
            3 => cut(&mut a.sample_pixels, keep),
            4 => cut(&mut a.views, keep),
            _ => cut(&mut a.config, keep),
        },
        Corruption::Value {
            field,
            index,
            value,
        } => {
            let v = match field {
                0 => &mut a.poses,
                1 => &mut a.joints,
                2 => &mut a.shape,
                _ => &mut a.sizes,
            };
            set(v, index, value);
        }
        Corruption::View { index, value } => set(&mut a.views, index, value),
        Corruption::Config { index, value } => set(&mut a.config, index, value),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(crate::io::tests::fuzz_cases(48)))]

    /// Any corruption gives a database or a `File` error, never a panic.
    #[test]
    fn corrupt_arrays_are_refused_not_panicked_on(
        count in 2i64..4,
        cs in proptest::collection::vec(corruption(), 1..4),
    ) {
        let mut a = arrays(count);
        for c in &cs {
            apply(&mut a, c);
        }
        match TemplateDatabase::from_arrays(&a, None, "fuzz") {
            Ok(db) => prop_assert_eq!(db.len(), NUM_TEMPLATES),
            Err(crate::Error::File { path, .. }) => prop_assert_eq!(path, "fuzz"),
            Err(e) => prop_assert!(false, "unexpected error {e:?}"),
        }
    }
}
