// secure.query (active label queries, secure/cbf/query.h) and secure.label (a domain's simulated
// person, experiments::Domain::Label).
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "python/src/common.h"
#include "secure/cbf/query.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"

namespace secure::python {

SECURE_PYTHON_TYPE(BarriersArg, "Union[Barrier, Sequence[Barrier], None]");
SECURE_PYTHON_TYPE(QueryResultTuple,
                   "Tuple[numpy.typing.NDArray[numpy.int64], Dict[str, Any]]");
SECURE_PYTHON_TYPE(LabelArray, "numpy.typing.NDArray[numpy.int32]");

void RegisterQuery(py::module_& m) {
  m.def(
      "query",
      [](BarriersArg barriers, ArrayLike pool, long k, const std::string& strategy,
         double radius, std::uint64_t seed) -> QueryResultTuple {
        std::vector<std::shared_ptr<Barrier>> held;
        if (py::isinstance<Barrier>(barriers)) {
          held.push_back(py::cast<std::shared_ptr<Barrier>>(barriers));
        } else if (!barriers.is_none()) {
          SECURE_CHECK(py::isinstance<py::sequence>(barriers) && !py::isinstance<py::str>(barriers),
                       "query: barriers must be a secure.Barrier, a sequence of them, or None");
          for (py::handle b : py::reinterpret_borrow<py::sequence>(barriers)) {
            SECURE_CHECK(py::isinstance<Barrier>(b), "query: barriers["
                                                         << held.size()
                                                         << "] is not a secure.Barrier");
            held.push_back(py::cast<std::shared_ptr<Barrier>>(b));
          }
        }
        const int dim = held.empty() ? -1 : held[0]->state_dim();
        const StatesArg s = States(pool, dim, "pool", /*allow_1d=*/false);
        cbf::QueryOptions o;
        o.strategy = FromString(cbf::kQueryStrategyNames, strategy, "strategy");
        o.k = k;
        o.diversity_radius = radius;
        o.seed = seed;
        cbf::QueryResult r;
        {
          py::gil_scoped_release release;
          std::vector<std::unique_lock<std::mutex>> locks;
          std::vector<const Barrier*> locked;
          std::vector<cbf::Barrier*> evaluators;
          for (const auto& b : held) {
            // The same barrier twice is one evaluator, locked once.
            if (std::find(locked.begin(), locked.end(), b.get()) == locked.end()) {
              locks.emplace_back(b->mutex);
              locked.push_back(b.get());
            }
            evaluators.push_back(b->evaluator.get());
          }
          r = cbf::SelectQueries(evaluators, s.map, o);
        }
        py::array_t<long long> indices(static_cast<py::ssize_t>(r.indices.size()));
        for (std::size_t i = 0; i < r.indices.size(); ++i)
          indices.mutable_at(static_cast<py::ssize_t>(i)) = r.indices[i];
        py::dict info;
        info["score"] = ToNumpy(r.score);
        info["h"] = ToNumpy(r.h);
        info["spread"] = ToNumpy(r.spread);
        info["strategy"] = strategy;
        return QueryResultTuple(py::make_tuple(indices, info));
      },
      py::arg("barriers"), py::arg("pool"), py::arg("k") = 50, py::arg("strategy") = "margin",
      py::arg("radius") = 0.0, py::arg("seed") = 0, R"doc(
Active label queries: the k states of `pool` (an (N, d) array of unlabelled candidates) a person
should label next, best first, as (indices (k,) int64, {"score", "h", "spread", "strategy"}).
strategy: "margin" (smallest |h|; one barrier), "disagreement" (largest spread of h over two or
more barriers), "shield-relevant" (margin; give it states a shielded run visited), "diversity"
(greedy k-centre over features normalised by the pool's standard deviation; no barrier needed)
or "random" (seeded). radius > 0: no two chosen states closer than it (normalised features), with
any strategy; fewer than k come back if the pool has no room. Raises ValueError on bad input.
Releases the GIL.)doc");

  m.def(
      "label",
      [](const std::string& domain, ArrayLike states, std::uint64_t seed) -> LabelArray {
        const std::unique_ptr<experiments::Domain> d = MakeDomain(domain, "full", py::dict());
        SECURE_CHECK(d->HasLabeller(), "label: the " << domain
                                                     << " domain has no labeller (domains with "
                                                        "one: "
                                                     << experiments::DomainRegistry::Global()
                                                            .ListOffering([](const experiments::Domain& x) {
                                                              return x.HasLabeller();
                                                            })
                                                     << ")");
        const StatesArg s = States(states, d->MakeEnvironment()->observation_dim(), "states",
                                   /*allow_1d=*/false);
        std::vector<int> labels;
        {
          py::gil_scoped_release release;
          labels = d->Label(s.map, seed);
        }
        py::array_t<int> out(static_cast<py::ssize_t>(labels.size()));
        for (std::size_t i = 0; i < labels.size(); ++i)
          out.mutable_at(static_cast<py::ssize_t>(i)) = labels[i];
        return LabelArray(std::move(out));
      },
      py::arg("domain"), py::arg("states"), py::arg("seed") = 0, R"doc(
A domain's simulated person labels states (an (N, observation_dim) array): 1 safe, 0
near-dangerous, -1 cannot say, as an (N,) int32 array. Domains with a labeller: the double
integrator (its ground truth), derby (nearest car within 0.14), panda-push (the label check's
physics), kitchen-cutting (the rule that made its near-dangerous states), coffee-placing (the
mean participant's thresholds, with their label noise 0.03). Raises ValueError for a domain
without one, or for rows it cannot judge.)doc");
}

}  // namespace secure::python
