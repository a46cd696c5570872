// Assist-View selection and conditioning on per-view tokens (avsplat/assist/assist_selection.h,
// avsplat/assist/condition_tokens.h).
#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "release_gil.h"

#include "avsplat/assist/assist_selection.h"
#include "avsplat/assist/condition_tokens.h"
#include "avsplat/core/names.h"

#include <pybind11/stl.h>

#include <limits>
#include <sstream>
#include <string>

namespace avsplat::python {

namespace {

FloatArray token_array(const py::handle& tokens) {
    return as_float_array(tokens, "tokens", {-1, -1, -1}, "S, P, C");
}

int to_int(long long v, const char* name, long long low) {
    if (v < low || v > std::numeric_limits<int>::max())
        throw py::value_error(std::string(name) + ": must be >= " + std::to_string(low) + " and fit int32, got " +
                              std::to_string(v));
    return int(v);
}

int dim(const FloatArray& a, int axis) {
    if (a.shape(axis) > std::numeric_limits<int>::max())
        throw py::value_error("tokens: dimension " + std::to_string(axis) + " is too large");
    return int(a.shape(axis));
}

// An integer index array of `shape` (-1: any); floats are refused rather than truncated.
ArrayOf<std::int64_t> index_array(const py::handle& obj, const char* arg, std::vector<py::ssize_t> shape,
                                  const char* dims) {
    py::array arr = py::module_::import("numpy").attr("asarray")(obj);
    const char kind = arr.dtype().kind();
    if (!(kind == 'i' || kind == 'u' || (arr.size() == 0 && kind == 'f')))
        throw py::value_error(std::string(arg) + ": expected an integer array of shape (" + dims + "), got dtype " +
                              py::str(arr.dtype()).cast<std::string>());
    return as_array<std::int64_t>(arr, arg, std::move(shape), dims, "integer");
}

const float* optional_vector(const py::handle& obj, const char* name, int C, FloatArray& keep) {
    if (obj.is_none()) return nullptr;
    keep = as_float_array(obj, name, {C}, "C");
    return keep.data();
}

}  // namespace

void bind_assist(py::module_& m) {
    py::class_<AssistSelection>(m, "AssistSelection",
                                "The assist views of every view, with the scores that chose them, the view descriptors "
                                "and reliabilities.")
        .def_property_readonly(
            "assists",
            [](const AssistSelection& r) {
                return copy_out(r.assists, {py::ssize_t(r.views), py::ssize_t(r.per_view)});
            },
            "(S, K) int64: the assists of each view in selection order, K = min(k, m, S - 1)")
        .def_property_readonly(
            "scores",
            [](const AssistSelection& r) { return copy_out(r.scores, {py::ssize_t(r.views), py::ssize_t(r.per_view)}); },
            "(S, K) float32: the winning score of each pick (column 0: 0.7 Sigma + mean_p max(0, sup) + beta q "
            "of the first assist, which Sigma alone chose)")
        .def_property_readonly(
            "descriptors",
            [](const AssistSelection& r) {
                return copy_out(r.descriptors, {py::ssize_t(r.views), py::ssize_t(r.channels)});
            },
            "(S, C) float32: d_s, the normalised mean token of each view")
        .def_property_readonly(
            "reliability",
            [](const AssistSelection& r) { return copy_out(r.reliability, {py::ssize_t(r.views)}); },
            "(S,) float32: q_s = v_s / max_t v_t, v_s the mean channel variance of the subsampled unit tokens")
        .def("__repr__", [](const AssistSelection& r) {
            std::ostringstream os;
            os << "AssistSelection(views=" << r.views << ", assists_per_view=" << r.per_view << ")";
            return os.str();
        });

    m.def(
        "select_assist_views",
        [](const ArrayLike& tokens, long long k, long long mm, long long p_sub, double lambda_div, double beta,
           double jitter, const py::int_& seed, const std::string& precision) {
            const FloatArray x = token_array(tokens);
            AssistOptions o;
            o.k = to_int(k, "k", 0);
            o.m = to_int(mm, "m", 0);
            o.p_sub = to_int(p_sub, "p_sub", 1);
            o.lambda_div = lambda_div;
            o.beta = beta;
            o.jitter = jitter;
            if (py::reinterpret_borrow<py::object>(seed) < py::int_(0) ||
                py::reinterpret_borrow<py::object>(seed) > py::int_(std::numeric_limits<std::uint64_t>::max()))
                throw py::value_error("seed: must lie in [0, 2**64)");
            o.seed = seed.cast<std::uint64_t>();
            o.precision = parse_precision(precision);
            ReleaseGil release;
            return select_assist_views(x.data(), dim(x, 0), dim(x, 1), dim(x, 2), o);
        },
        py::arg("tokens"), py::arg("k") = 4, py::arg("m") = 8, py::arg("p_sub") = 64, py::arg("lambda_div") = 0.3,
        py::arg("beta") = 0.1, py::arg("jitter") = 0.0, py::arg("seed") = 0, py::arg("precision") = "float32",
        R"doc(
Pick, for every view, a small, relevant and diverse set of assist views (AVSplat, Algorithm 1).

For view s: descriptors d = normalised mean token, Sigma = clip(D D^T, -1, 1),
Delta = max(1 - Sigma, 0); Xh_s = the rows floor(j P / p_sub) (all rows if p_sub >= P), each
normalised; reliability q = v / max v with v the mean over channels of the population variance
over the rows of Xh; the pool N(s) = the min(m, S - 1) views t != s of largest Sigma[s, t]
(ties to the smaller index); sup_t[p] = max_j Xh_s[p] . Xh_t[j]. Greedy starts with the first
of N(s), c = its sup, then adds the t of largest
0.7 Sigma[s, t] + lambda_div min_{u in A} Delta[t, u] + mean_p max(0, sup_t[p] - c[p]) + beta q_t
(ties to the smaller index) until min(k, m, S - 1) assists, updating c = max(c, sup_t). With
probability `jitter` per view (seeded by `seed` and the view index only), the last assist is
replaced by a uniform draw from N(s) minus the chosen set. S = 1: no assists.

Parameters
----------
tokens : array_like, shape (S, P, C)
    Per-view tokens, float32 (float64 and other real dtypes are converted once).
k : int
    Assists per view.
m : int
    Size of the candidate pool.
p_sub : int
    Token rows per view used for the support.
lambda_div : float
    Weight of diversity.
beta : float
    Weight of reliability.
jitter : float
    Probability of replacing the last assist by a seeded random draw from the pool.
seed : int
    Seed of the jitter.
precision : {"float32", "float64"}
    Scalar of the support GEMMs; the rest is float64.

Returns
-------
AssistSelection
    ``assists`` (S, K) int64 in selection order, ``scores`` (S, K) float32, ``descriptors``
    (S, C) float32, ``reliability`` (S,) float32.

Raises
------
ValueError
    For a bad shape or option and for a non-finite token, naming its (view, token, channel)
    index.

Notes
-----
Deterministic; independent of the thread count.)doc");

    m.def(
        "assist_objective",
        [](const ArrayLike& tokens, long long s, const ArrayLike& A, double beta, double lambda_div,
           long long p_sub) {
            const FloatArray x = token_array(tokens);
            const ArrayOf<std::int64_t> a = index_array(A, "A", {-1}, "N");
            const std::vector<std::int64_t> members(a.data(), a.data() + a.size());
            const int s_int = to_int(s, "s", 0);
            const int p = to_int(p_sub, "p_sub", 1);
            ReleaseGil release;
            return assist_objective(x.data(), dim(x, 0), dim(x, 1), dim(x, 2), s_int, members, beta, lambda_div, p);
        },
        py::arg("tokens"), py::arg("s"), py::arg("A"), py::arg("beta") = 0.1, py::arg("lambda_div") = 0.3,
        py::arg("p_sub") = 64,
        R"doc(
The objective of an assist set A of view s, in float64.

F(A) = mean_p max_{t in A} sup_t[p] + beta mean_{t in A} q_t - lambda_div * (mean over ordered
pairs t != u in A of Sigma[t, u]), with sup, q and Sigma as in ``select_assist_views`` (the pair
term is 0 for one assist). With beta = lambda_div = 0 it is the coverage term alone, for
comparing the greedy choice with an exhaustive search.

Parameters
----------
tokens : array_like, shape (S, P, C)
    Per-view tokens.
s : int
    The view.
A : sequence of int
    Distinct view indices != s.
beta, lambda_div : float
    As ``select_assist_views``.
p_sub : int
    As ``select_assist_views``.

Returns
-------
float
    F(A).

Raises
------
ValueError
    For a bad shape, index or option and for a non-finite token.)doc");

    m.def(
        "condition_tokens",
        [](const ArrayLike& tokens, const ArrayLike& assists, const ArrayLike& wq, const ArrayLike& wk,
           const ArrayLike& wv, const ArrayLike& wo, long long heads, double gate, const OptionalArrayLike& bq,
           const OptionalArrayLike& bk, const OptionalArrayLike& bv, const OptionalArrayLike& bo, const std::string& precision) {
            const FloatArray x = token_array(tokens);
            const int S = dim(x, 0), P = dim(x, 1), C = dim(x, 2);
            const ArrayOf<std::int64_t> a = index_array(assists, "assists", {S, -1}, "S, K");
            if (a.shape(1) > std::numeric_limits<int>::max()) throw py::value_error("assists: too many per view");
            FloatArray w[4], b[4];
            const char* wnames[4] = {"wq", "wk", "wv", "wo"};
            const py::handle wh[4] = {wq, wk, wv, wo};
            for (int i = 0; i < 4; ++i) w[i] = as_float_array(wh[i], wnames[i], {C, C}, "C, C");
            ConditionWeights cw;
            cw.wq = w[0].data();
            cw.wk = w[1].data();
            cw.wv = w[2].data();
            cw.wo = w[3].data();
            cw.bq = optional_vector(bq, "bq", C, b[0]);
            cw.bk = optional_vector(bk, "bk", C, b[1]);
            cw.bv = optional_vector(bv, "bv", C, b[2]);
            cw.bo = optional_vector(bo, "bo", C, b[3]);
            ConditionOptions o;
            o.heads = to_int(heads, "heads", 1);
            o.gate = gate;
            o.precision = parse_precision(precision);
            py::array_t<float> out({py::ssize_t(S), py::ssize_t(P), py::ssize_t(C)});
            float* dst = out.mutable_data();
            {
                ReleaseGil release;
                condition_tokens(x.data(), S, P, C, a.data(), int(a.shape(1)), cw, o, dst);
            }
            return out;
        },
        py::arg("tokens"), py::arg("assists"), py::arg("wq"), py::arg("wk"), py::arg("wv"), py::arg("wo"),
        py::arg("heads"), py::arg("gate") = 1.0, py::arg("bq") = py::none(), py::arg("bk") = py::none(),
        py::arg("bv") = py::none(), py::arg("bo") = py::none(), py::arg("precision") = "float32",
        R"doc(
Let each view attend once to the tokens of its assists (gated multi-head cross-attention).

For view s: Q = X_s Wq + bq, K = [X_t Wk + bk] and V = [X_t Wv + bv] over t in assists[s]
(concatenated in order, K P rows); `heads` heads of d = C / heads channels each:
O_h = softmax(Q_h K_h^T / sqrt(d)) V_h (row maximum subtracted); C_s = [O_1 .. O_heads] Wo + bo;
the output is X_s + gate * C_s. With K = 0 the tokens pass through.

Parameters
----------
tokens : array_like, shape (S, P, C)
    Per-view tokens, float32.
assists : array_like of int, shape (S, K)
    View indices, e.g. ``AssistSelection.assists``.
wq, wk, wv, wo : array_like, shape (C, C)
    Row-vector maps (x -> x W).
heads : int
    Number of heads; must divide C.
gate : float
    Weight of the conditioning.
bq, bk, bv, bo : array_like, shape (C,), optional
    Biases.
precision : {"float32", "float64"}
    float32: float32 GEMMs and exponentials, softmax sums in float64.

Returns
-------
ndarray, shape (S, P, C), float32
    The conditioned tokens.

Raises
------
ValueError
    For a bad shape, heads not dividing C, an assist index out of range (naming
    assists[s, j]) and non-finite tokens, weights or biases.

Notes
-----
Independent of the thread count.)doc");
}

}  // namespace avsplat::python
