//! Parameters by name: the bridge between a burn module and a flat file of
//! named tensors. Names are the module's field path ("enc.0.conv1.weight"),
//! so a weight file is readable from numpy or PyTorch and a missing or
//! misshapen tensor can be reported by name.

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::backend::Backend;
use burn::tensor::{Tensor, TensorData};
use std::collections::BTreeMap;

/// A named parameter: pgrf's one tensor record type (shape + row-major f32).
pub(crate) use pgrf_core::record::Tensor as NamedTensor;

struct Collector {
    path: Vec<String>,
    out: BTreeMap<String, NamedTensor>,
}

impl<B: Backend> ModuleVisitor<B> for Collector {
    fn enter_module(&mut self, name: &str, _container: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container: &str) {
        self.path.pop();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<B, D>>) {
        let t = param.val();
        let shape = t.dims().to_vec();
        let values: Vec<f32> = t
            .into_data()
            .convert::<f32>()
            .to_vec()
            .expect("converted to f32");
        self.out
            .insert(self.path.join("."), NamedTensor { shape, values });
    }
}

/// Every float parameter of `module`, by path.
pub fn collect<B: Backend, M: Module<B>>(module: &M) -> BTreeMap<String, NamedTensor> {
    let mut c = Collector {
        path: Vec::new(),
        out: BTreeMap::new(),
    };
    module.visit(&mut c);
    c.out
}

/// One way named tensors fail to fit a network.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TensorFault {
    /// A parameter of the network that is not among the tensors.
    #[error("{0} is missing")]
    Missing(String),
    /// A tensor whose shape is not its parameter's.
    #[error("{name} has shape {found:?}, the network needs {wanted:?}")]
    Shape {
        /// The tensor's name.
        name: String,
        /// Its shape.
        found: Vec<usize>,
        /// The parameter's.
        wanted: Vec<usize>,
    },
    /// A tensor that is no parameter of the network.
    #[error("{0} is not part of this network")]
    Unknown(String),
    /// Tensor counts that do not match a network's convolutions (a weight
    /// and a bias each).
    #[error("{from} and {into} tensors for the {convolutions} convolutions of the network")]
    Count {
        /// Tensors of the file.
        from: usize,
        /// Tensors of the network.
        into: usize,
        /// Convolutions of the network.
        convolutions: usize,
    },
    /// A convolution weight that is not `[out, in, kh, kw]`.
    #[error("{0} is not 4-dimensional")]
    NotConvolution(String),
    /// A prior's weights for a flow that reads none.
    #[error("the flow model reads no prior")]
    NoPrior,
}

/// Why named tensors do not fit a network: every fault found (a caller may
/// look for a missing or misshapen tensor by name); the message lists the
/// first three.
#[derive(Clone, Debug, PartialEq)]
pub struct Mismatch(pub Vec<TensorFault>);

impl From<TensorFault> for Mismatch {
    fn from(f: TensorFault) -> Mismatch {
        Mismatch(vec![f])
    }
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let shown: Vec<String> = self.0.iter().take(3).map(|p| p.to_string()).collect();
        f.write_str(&shown.join("; "))?;
        if self.0.len() > 3 {
            write!(f, " (and {} more)", self.0.len() - 3)?;
        }
        Ok(())
    }
}

impl std::error::Error for Mismatch {}

struct Assigner<'a, B: Backend> {
    path: Vec<String>,
    values: &'a BTreeMap<String, NamedTensor>,
    device: B::Device,
    used: usize,
    problems: Vec<TensorFault>,
}

impl<B: Backend> ModuleMapper<B> for Assigner<'_, B> {
    fn enter_module(&mut self, name: &str, _container: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container: &str) {
        self.path.pop();
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<B, D>>) -> Param<Tensor<B, D>> {
        let name = self.path.join(".");
        let (id, tensor, mapper) = param.consume();
        let Some(v) = self.values.get(&name) else {
            self.problems.push(TensorFault::Missing(name));
            return Param::from_mapped_value(id, tensor, mapper);
        };
        let want = tensor.dims().to_vec();
        if v.shape != want {
            self.problems.push(TensorFault::Shape {
                name,
                found: v.shape.clone(),
                wanted: want,
            });
            return Param::from_mapped_value(id, tensor, mapper);
        }
        self.used += 1;
        let data = TensorData::new(v.values.clone(), v.shape.clone());
        // Keep the parameter trainable if it was (autodiff backends).
        let loaded = Tensor::<B, D>::from_data(data, &self.device)
            .set_require_grad(tensor.is_require_grad());
        Param::from_mapped_value(id, loaded, mapper)
    }
}

/// Load `values` into `module`; every parameter must be present with its
/// exact shape and no tensor may be left over, otherwise the file was made for
/// another architecture and the error lists (the first few) differences.
pub fn assign<B: Backend, M: Module<B>>(
    module: M,
    values: &BTreeMap<String, NamedTensor>,
    device: &B::Device,
) -> Result<M, Mismatch> {
    let mut a = Assigner {
        path: Vec::new(),
        values,
        device: device.clone(),
        used: 0,
        problems: Vec::new(),
    };
    let module = module.map(&mut a);
    let mut problems = a.problems;
    if problems.is_empty() && a.used != values.len() {
        let known = collect::<B, M>(&module);
        problems.extend(
            values
                .keys()
                .filter(|k| !known.contains_key(*k))
                .map(|k| TensorFault::Unknown(k.clone())),
        );
    }
    if problems.is_empty() {
        return Ok(module);
    }
    Err(Mismatch(problems))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::sid_unet::SidUnetConfig;
    use crate::backend::Cpu;

    #[test]
    fn names_follow_the_module_tree_and_round_trip() {
        let device = Default::default();
        let a = SidUnetConfig::new().with_width(2).init::<Cpu>(&device);
        let named = collect::<Cpu, _>(&a);
        let count: usize = named.values().map(|t| t.values.len()).sum();
        assert_eq!(count, a.num_params());
        assert!(named
            .keys()
            .all(|k| k.ends_with("weight") || k.ends_with("bias")));
        let b = SidUnetConfig::new().with_width(2).init::<Cpu>(&device);
        assert_ne!(collect::<Cpu, _>(&b), named);
        let b = assign(b, &named, &device).unwrap();
        assert_eq!(collect::<Cpu, _>(&b), named);
    }

    #[test]
    fn another_width_is_refused_by_name() {
        let device = Default::default();
        let a = SidUnetConfig::new().with_width(2).init::<Cpu>(&device);
        let b = SidUnetConfig::new().with_width(4).init::<Cpu>(&device);
        let e = assign(b, &collect::<Cpu, _>(&a), &device).unwrap_err();
        assert!(e.to_string().contains("has shape"), "{e}");
        // Every misshapen tensor, by name; the message shows three.
        assert!(e.0.len() > 3, "{e:?}");
        assert!(e
            .0
            .iter()
            .all(|f| matches!(f, TensorFault::Shape { found, wanted, .. } if found != wanted)));
        assert!(
            e.to_string()
                .ends_with(&format!("(and {} more)", e.0.len() - 3)),
            "{e}"
        );
        let mut extra = collect::<Cpu, _>(&a);
        extra.insert(
            "stray.weight".into(),
            NamedTensor {
                shape: vec![1],
                values: vec![0.0],
            },
        );
        let c = SidUnetConfig::new().with_width(2).init::<Cpu>(&device);
        let e = assign(c, &extra, &device).unwrap_err();
        assert_eq!(e.0, vec![TensorFault::Unknown("stray.weight".into())]);
        assert_eq!(e.to_string(), "stray.weight is not part of this network");
    }
}
