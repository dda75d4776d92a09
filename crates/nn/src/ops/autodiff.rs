//! pgrf's operations as nodes of burn's autodiff graph: each forward runs
//! the inner backend's operation and records what its backward needs (the
//! inputs, as checkpoints); each backward consumes the node's output
//! gradient once and registers a gradient for every parent that needs one,
//! from the inner backend's `pgrf_*_backward`. Built after burn's own
//! convolution and activation nodes (burn-autodiff 0.21, `ops/module.rs`,
//! `ops/activation.rs`).

use super::{Needed, NormSpec, PgrfOps};
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{unary, Backward, Ops, OpsKind};
use burn::backend::autodiff::NodeId;
use burn::backend::Autodiff;
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions, FloatTensor, ModuleOps};

/// The backward of a convolution-like node (parents: input, weight, bias):
/// the gradients the parents need from `$backward` of the inner backend,
/// registered on them. A macro because burn 0.21 does not export the type
/// of a node's parents.
macro_rules! conv_backward {
    ($B:ty, $ops:expr, $grads:expr, $checkpointer:expr, $backward:ident) => {{
        let dy = $grads.consume::<$B>(&$ops.node);
        let (xs, ws, bs, options) = $ops.state;
        let x = $checkpointer.retrieve_node_output::<FloatTensor<$B>>(xs);
        let w = $checkpointer.retrieve_node_output::<FloatTensor<$B>>(ws);
        let b = $checkpointer.retrieve_node_output::<FloatTensor<$B>>(bs);
        let [px, pw, pb] = $ops.parents;
        let needed = Needed {
            x: px.is_some(),
            weight: pw.is_some(),
            bias: pb.is_some(),
        };
        let g = <$B>::$backward(x, w, Some(b), dy, options, needed);
        for (parent, grad) in [(px, g.x), (pw, g.weight), (pb, g.bias)] {
            if let (Some(node), Some(grad)) = (parent, grad) {
                $grads.register::<$B>(node.id, grad);
            }
        }
    }};
}

/// The graph node of a convolution-like operation with a bias: records the
/// three inputs as checkpoints (when any needs a gradient) and runs
/// `forward` on the inner backend. `node`'s backward is `conv_backward!`.
fn conv_node<B, C, O, N>(
    node: N,
    x: FloatTensor<Autodiff<B, C>>,
    weight: FloatTensor<Autodiff<B, C>>,
    bias: FloatTensor<Autodiff<B, C>>,
    options: O,
    forward: impl FnOnce(FloatTensor<B>, FloatTensor<B>, Option<FloatTensor<B>>, O) -> FloatTensor<B>,
) -> FloatTensor<Autodiff<B, C>>
where
    B: PgrfOps,
    C: CheckpointStrategy,
    O: Clone + Send + std::fmt::Debug + 'static,
    N: Backward<B, 3, State = (NodeId, NodeId, NodeId, O)>,
{
    match node
        .prepare::<C>([x.node.clone(), weight.node.clone(), bias.node.clone()])
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(mut prep) => {
            let state = (
                prep.checkpoint(&x),
                prep.checkpoint(&weight),
                prep.checkpoint(&bias),
                options.clone(),
            );
            prep.finish(
                state,
                forward(x.primitive, weight.primitive, Some(bias.primitive), options),
            )
        }
        OpsKind::UnTracked(prep) => prep.finish(forward(
            x.primitive,
            weight.primitive,
            Some(bias.primitive),
            options,
        )),
    }
}

impl<B: PgrfOps, C: CheckpointStrategy> PgrfOps for Autodiff<B, C> {
    fn pgrf_kernels() -> bool {
        B::pgrf_kernels()
    }

    fn pgrf_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Conv2d;

        impl<B: PgrfOps> Backward<B, 3> for Conv2d {
            type State = (NodeId, NodeId, NodeId, ConvOptions<2>);

            fn backward(
                self,
                ops: Ops<Self::State, 3>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                conv_backward!(B, ops, grads, checkpointer, pgrf_conv2d_backward);
            }
        }

        // pgrf's networks give every convolution a bias; without one, burn's node.
        let Some(bias) = bias else {
            return <Self as ModuleOps<Self>>::conv2d(x, weight, None, options);
        };
        conv_node::<B, C, _, _>(Conv2d, x, weight, bias, options, B::pgrf_conv2d)
    }

    fn pgrf_conv_transpose2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct ConvTranspose2d;

        impl<B: PgrfOps> Backward<B, 3> for ConvTranspose2d {
            type State = (NodeId, NodeId, NodeId, ConvTransposeOptions<2>);

            fn backward(
                self,
                ops: Ops<Self::State, 3>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                conv_backward!(B, ops, grads, checkpointer, pgrf_conv_transpose2d_backward);
            }
        }

        let Some(bias) = bias else {
            return <Self as ModuleOps<Self>>::conv_transpose2d(x, weight, None, options);
        };
        conv_node::<B, C, _, _>(
            ConvTranspose2d,
            x,
            weight,
            bias,
            options,
            B::pgrf_conv_transpose2d,
        )
    }

    fn pgrf_leaky_relu(x: FloatTensor<Self>, slope: f32) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct LeakyRelu;

        impl<B: PgrfOps> Backward<B, 1> for LeakyRelu {
            type State = (NodeId, f32);

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let (xs, slope) = ops.state;
                let x = checkpointer.retrieve_node_output::<FloatTensor<B>>(xs);
                unary::<B, _>(ops.parents, ops.node, grads, |dy| {
                    B::pgrf_leaky_relu_backward(x, dy, slope)
                });
            }
        }

        match LeakyRelu
            .prepare::<C>([x.node.clone()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let state = (prep.checkpoint(&x), slope);
                prep.finish(state, B::pgrf_leaky_relu(x.primitive, slope))
            }
            OpsKind::UnTracked(prep) => prep.finish(B::pgrf_leaky_relu(x.primitive, slope)),
        }
    }

    fn pgrf_silu(x: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Silu;

        impl<B: PgrfOps> Backward<B, 1> for Silu {
            type State = NodeId;

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let x = checkpointer.retrieve_node_output::<FloatTensor<B>>(ops.state);
                unary::<B, _>(ops.parents, ops.node, grads, |dy| {
                    B::pgrf_silu_backward(x, dy)
                });
            }
        }

        match Silu
            .prepare::<C>([x.node.clone()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let state = prep.checkpoint(&x);
                prep.finish(state, B::pgrf_silu(x.primitive))
            }
            OpsKind::UnTracked(prep) => prep.finish(B::pgrf_silu(x.primitive)),
        }
    }

    fn pgrf_group_norm(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        spec: NormSpec,
    ) -> FloatTensor<Self> {
        if spec.silu {
            // Recorded as two operations, each with its own backward.
            let plain = NormSpec {
                silu: false,
                ..spec
            };
            return Self::pgrf_silu(Self::pgrf_group_norm(x, gamma, beta, plain));
        }
        #[derive(Debug)]
        struct GroupNorm;

        impl<B: PgrfOps> Backward<B, 3> for GroupNorm {
            type State = (NodeId, NodeId, NormSpec);

            fn backward(
                self,
                ops: Ops<Self::State, 3>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let dy = grads.consume::<B>(&ops.node);
                let (xs, gs, spec) = ops.state;
                let x = checkpointer.retrieve_node_output::<FloatTensor<B>>(xs);
                let gamma = checkpointer.retrieve_node_output::<FloatTensor<B>>(gs);
                let g = B::pgrf_group_norm_backward(x, gamma, dy, spec);
                for (parent, grad) in ops.parents.into_iter().zip(g) {
                    if let Some(node) = parent {
                        grads.register::<B>(node.id, grad);
                    }
                }
            }
        }

        match GroupNorm
            .prepare::<C>([x.node.clone(), gamma.node.clone(), beta.node.clone()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                // Recorded: each window on its own (`NormSpec::blend`).
                let spec = NormSpec {
                    blend: false,
                    ..spec
                };
                let state = (prep.checkpoint(&x), prep.checkpoint(&gamma), spec);
                let out = B::pgrf_group_norm(x.primitive, gamma.primitive, beta.primitive, spec);
                prep.finish(state, out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::pgrf_group_norm(
                x.primitive,
                gamma.primitive,
                beta.primitive,
                spec,
            )),
        }
    }
}
