// The typed results of OnlineSmoother2/3 (docs/python.md, "Results"): UpdateStats (update(),
// finalize(), solve_deferred()), OnlineStats (stats()), AddGraphResult (add_graph()), Closure
// (closures()) and RefineResult (refine()), each a record (record.h).
#include "smoother_results.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "bindings.h"
#include "record.h"

namespace arbor::python {

void defineSmootherResults(py::module_& m) {
  using U = UpdateStats;
  const Record<U> update_stats =
      Record<U>(m, "UpdateStats",
                "One update's statistics: update(), finalize(), solve_deferred().")
          .field("new_factors", &U::new_factors, "factors added by this update")
          .field("new_variables", &U::new_variables, "poses added by this update")
          .field("cliques_reeliminated", &U::cliques_reeliminated, "cliques of the new top")
          .field("variables_reeliminated", &U::variables_reeliminated,
                 "frontal variables of the new top")
          .field("cliques_updated", &U::cliques_updated, "cliques given a rank update instead")
          .field("variables_relinearized", &U::variables_relinearized, "variables relinearised")
          .field("indeterminate_cliques", &U::indeterminate_cliques,
                 "nearly singular cliques that had to be damped")
          .field("cliques_solved", &U::cliques_solved, "cliques re-solved by back-substitution")
          .field("cliques_deferred", &U::cliques_deferred,
                 "cliques whose solve solve_budget_mb left for later")
          .field("time_s", &U::time_s, "wall time of the update");

  using S = OnlineStats;
  Record<S>(m, "OnlineStats",
            "The online layer's counts (stats()): the robust ones are those of `arbor replay "
            "--robust --json`'s robust object.")
      .field("poses", &S::poses, "poses held")
      .field("edges_accepted", &S::edges_accepted, "edges handed to the smoother")
      .field("edges_duplicate", &S::edges_duplicate, "edges given twice")
      .field("edges_rejected", &S::edges_rejected, "edges refused")
      .field("priors_accepted", &S::priors_accepted, "pose and position priors held")
      .field("priors_rejected", &S::priors_rejected, "priors refused")
      .field("components", &S::components, "connected components now")
      .field("joins", &S::joins, "edges that joined two components")
      .field("anchors_released", &S::anchors_released, "component anchors released")
      .field("updates", &S::updates, "updates run")
      .field("total_update_time_s", &S::total_update_time_s, "wall time of every update")
      .field("edges_disabled", &S::edges_disabled, "accepted edges disabled now")
      .field("pairs_disabled", &S::pairs_disabled, "id pairs disabled now")
      .field("closures_inlier", &S::closures_inlier, "robust: closures held as inliers")
      .field("closures_outlier", &S::closures_outlier, "robust: closures rejected")
      .field("closures_trusted", &S::closures_trusted, "robust: closures added as trusted")
      .field("closures_excluded", &S::closures_excluded, "robust: closures excluded")
      .field("closures_graduating", &S::closures_graduating, "robust: closures not settled yet")
      .field("closures_unconfirmed", &S::closures_unconfirmed, "robust: inliers not confirmed")
      .field("rechecks_bounded", &S::rechecks_bounded, "robust: rechecks cut by their bound")
      .field("closures_kept_at_word", &S::closures_kept_at_word,
             "robust: closures kept at Ω's word")
      .field("graduation_steps", &S::graduation_steps, "robust: weight changes by graduation")
      .field("graduation_updates", &S::graduation_updates, "robust: extra updates of graduation")
      .field("warm_up_relinearizations", &S::warm_up_relinearizations,
             "robust: relinearisations of the warm-up")
      .field("closure_threshold", &S::closure_threshold, "robust: the c² in use")
      .field("closure_threshold_at_end", &S::closure_threshold_at_end, "robust: the c² at the end")
      .field("noise_scale", &S::noise_scale, "robust: the noise scale")
      .field("noise_samples", &S::noise_samples, "robust: samples of the noise scale")
      .field("noise_scale_estimated", &S::noise_scale_estimated,
             "robust: the noise scale is estimated (not Ω at its word)")
      .field("reseeds", &S::reseeds, "rebuilds by refine(reseed=True) that were kept")
      .field("total_reseed_time_s", &S::total_reseed_time_s, "wall time of those rebuilds")
      .nested("last_update", &S::last_update, update_stats, "the last update's UpdateStats");

  Record<AddGraphResult>(m, "AddGraphResult", "What add_graph() returns.")
      .field("accepted", &AddGraphResult::accepted, "edges, priors and factors accepted")
      .field("duplicate", &AddGraphResult::duplicate, "edges given twice");

  Record<Closure>(m, "Closure", "One loop closure of closures() (robust options).")
      .field("from_id", &Closure::from_id, "the edge's from id")
      .field("to_id", &Closure::to_id, "the edge's to id")
      .field("weight", &Closure::weight, "its inlier weight in the smoother")
      .field("residual", &Closure::residual, "eᵀΩe at its last check")
      .field("status", &Closure::status, "inlier | outlier | trusted | excluded")
      .field("graduating", &Closure::graduating, "still being graduated or held in the warm-up");

  using R = RefineResult;
  Record<R>(m, "RefineResult", "What refine() returns (F_* are Σρ when robust).")
      .field("poses", &R::poses, "poses of the snapshot solved")
      .field("edges", &R::edges, "edges of the snapshot solved")
      .field("F_incremental", &R::F_incremental, "F of the incremental estimate")
      .field("F_batch", &R::F_batch, "F of the batch estimate")
      .field("relative_gap", &R::relative_gap, "(F_incremental − F_batch) / F_batch")
      .field("winner", &R::winner, "incremental | lm | gnc | rtr")
      .field("margin", &R::margin, "|F of the runner-up − F of the winner|")
      .field("max_translation_diff", &R::max_translation_diff,
             "largest translation difference of incremental and batch")
      .field("max_rotation_diff", &R::max_rotation_diff, "largest rotation difference (radians)")
      .field("iterations", &R::iterations, "iterations of the batch solver")
      .field("time_s", &R::time_s, "wall time of the solves")
      .field("certified", &R::certified, "rtr: certified optimal; else None")
      .field("rank", &R::rank, "rtr: the staircase's rank; else None")
      .field("lambda_min", &R::lambda_min, "rtr: the certificate's λ_min; else None")
      .field("robust", &R::robust, "with robust options (GNC)")
      .field("judged", &R::judged, "robust: edges GNC weighted")
      .field("rejected", &R::rejected, "robust: of them, outliers in the batch estimate")
      .field("inlier_threshold", &R::inlier_threshold, "robust: GNC's c²")
      .field("rtr_skipped", &R::rtr_skipped, "rtr: why the staircase did not run ('' if it did)")
      .field("reseeded", &R::reseeded, "the smoother was rebuilt from the winner's estimate")
      .field("reseed_rejected", &R::reseed_rejected, "a rebuild was tried but not kept")
      .field("ids", &R::ids, "the pose ids of the snapshot (int64)")
      .field("estimate", &R::estimate, "the batch estimate, one row per id");
}

}  // namespace arbor::python
