// secure render: one evaluation episode of a method, as `secure eval` plays it, drawn frame by
// frame by the domain's offscreen renderer into an MP4 (ffmpeg) and/or a directory of PPM images.
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "eval_models.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/eval/policy_eval.h"
#include "secure/eval/overlay.h"
#include "secure/eval/render.h"
#include "secure/eval/video.h"
#include "secure/experiments/experiment.h"

namespace secure::cli {
namespace {

eval::OverlayStep OverlayStepOf(const eval::FrameInfo& info) {
  eval::OverlayStep step;
  step.step = info.step;
  step.h = info.h;
  if (info.decision != nullptr) {
    step.status = ToString(shield::kStatusNames, info.decision->status);
    step.intervened = info.decision->intervened;
  }
  step.collided = info.collided;
  step.reached_goal = info.reached_goal;
  return step;
}

struct RenderCommand {
  std::string domain, method, run_dir, policy_path, barrier_path, airl_reward_path, out, frames_dir;
  std::uint64_t seed = 0;
  long episode = 0;
  eval::VideoOptions video;
  shield::ShieldOptions shield;
  ShieldFlags shield_flags;
  const Config* config = nullptr;
  bool json = false;
  bool no_overlay = false, no_panel = false;

  void Register(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand(
        "render",
        "Render one evaluation episode of a method (the episode `secure eval` plays for that "
        "seed and index) with the domain's offscreen renderer: an MP4 video (ffmpeg) and/or PPM "
        "frames. The shield flags marked =preset default to the domain's preset (`secure domains "
        "NAME` lists it)");
    AddDomainOption(cmd, &domain)->required();
    AddConfigFlag(cmd, *config);  // the domain's options: section <domain's>, key `domain`
    cmd->add_option("--method", method,
                    "one method: bc, airl, secure, secure-random-safe, secure-no-resampling, "
                    "bc+shield, secure-myopic, joint, cbf-qp, secure-qp, first-safe, cbf-grad")
        ->required();
    cmd->add_option("--run", run_dir,
                    "a `secure demo --out` or `secure experiment --out` directory: the models of "
                    "seed-<seed>/ are used")
        ->transform(DirectoryPath());
    cmd->add_option("--policy", policy_path,
                    "the method's policy model (BC, AIRL or joint; instead of / overriding --run)");
    cmd->add_option("--airl-reward", airl_reward_path,
                    "AIRL's reward model, the task value of the shield's aggregation top-q "
                    "(instead of / overriding --run)");
    cmd->add_option("--barrier", barrier_path,
                    "barrier model (flat or per-obstacle), or 'ground-truth' for a domain that "
                    "has one (shielded methods; instead of / overriding --run)");
    AddSeedOption(cmd, "--seed", &seed,
                  "training seed: seed-<seed>/ of --run, and the evaluation stream "
                  "`secure eval` uses for it (default 0, eval's --first-seed)");
    cmd->add_option(
           "--episode", episode,
           "the episode (0-based) of that seed's evaluation, below " + std::to_string(kMaxEpisodes))
        ->capture_default_str();
    cmd->add_option("--out", out, "the MP4 file to write (needs ffmpeg)");
    cmd->add_option("--frames-dir", frames_dir,
                    "also (or instead) write every frame as DIR/frame-NNNNNN.ppm")
        ->transform(DirectoryPath());
    cmd->add_option("--width", video.width, "frame width in pixels (even)")->capture_default_str();
    cmd->add_option("--height", video.height, "frame height in pixels (even)")
        ->capture_default_str();
    cmd->add_option("--fps", video.fps, "frames per second of the video")->capture_default_str();
    cmd->add_flag("--no-overlay", no_overlay,
                  "draw the frames as the domain renders them: without the overlay of the step, "
                  "h(s), the shield's status, interventions (orange border) and collisions (red), "
                  "and the plot of h over the episode at the bottom");
    cmd->add_flag("--no-panel", no_panel, "the overlay without the plot of h at the bottom");
    shield_flags.Add(cmd, &shield, /*domain_preset=*/true);  // `secure domains NAME` lists it
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    experiments::ExperimentOptions section;
    const std::unique_ptr<experiments::Domain> d =
        MakeConfiguredDomain(domain, false, *config, &section);
    const std::unique_ptr<domains::Environment> env = d->MakeEnvironment();
    SECURE_CHECK(env->CanRender(),
                 "the " << domain << " domain cannot render (no offscreen renderer)");
    const std::vector<eval::Method> methods = eval::ParseMethods(method);
    SECURE_CHECK(methods.size() == 1,
                 "--method = '" << method << "': give one method (`secure render` draws one "
                                << "episode)");
    const eval::Method m = methods.front();
    const shield::ShieldOptions shield_options =
        OverlayShieldFlags(section.shield, shield_flags, &shield);
    shield_options.Validate();
    CheckRange("--episode", episode, 0, kMaxEpisodes - 1);
    video.Validate();
    SECURE_CHECK(!out.empty() || !frames_dir.empty(), "give --out FILE.mp4 or --frames-dir DIR");
    SECURE_CHECK(!run_dir.empty() || !policy_path.empty(),
                 "give --run DIR (with --seed K) or --policy FILE");
    ModelSources sources;
    sources.run_dir = run_dir;
    sources.barrier = barrier_path;
    sources.airl_reward = airl_reward_path;
    if (eval::UsesBcPolicy(m)) {
      sources.bc = policy_path;
    } else if (eval::UsesJointPolicy(m)) {
      sources.joint = policy_path;
    } else {
      sources.airl = policy_path;
    }
    const SeedModelSet models(sources, *d, domain, *env, methods, seed, shield_options);
    // Outputs are opened before the episode runs: a missing ffmpeg or an unusable place fails
    // at once.
    if (!frames_dir.empty()) CreateDirectories(frames_dir);
    std::optional<eval::VideoWriter> writer;
    if (!out.empty()) writer.emplace(out, video);
    eval::OverlayOptions overlay_options;
    overlay_options.title = ToString(eval::kMethodNames, m) + ", seed " + std::to_string(seed) +
                            ", episode " + std::to_string(episode);
    overlay_options.max_steps = env->max_steps();
    overlay_options.panel = !no_panel;
    eval::EpisodeOverlay overlay(overlay_options);
    long index = 0;
    const eval::RenderedEpisode r = eval::RenderEpisode(
        *env, m, models.models(), shield_options, eval::EvaluationSeed(seed), episode, video.width,
        video.height, [&](domains::Frame& frame, const eval::FrameInfo& info) {
                              if (!no_overlay) overlay.Draw(OverlayStepOf(info), frame);
                              if (!frames_dir.empty()) {
                                char name[32];
                                std::snprintf(name, sizeof name, "/frame-%06ld.ppm", index);
                                eval::WritePpm(frames_dir + name, frame);
                              }
                              if (writer) writer->Write(frame);
                              ++index;
                            });
    if (writer) writer->Finish();
    const std::string outcome =
        std::string(r.success ? "success" : "no success") + ", " +
        (r.dangerous ? "dangerous (" + std::to_string(r.collision_events) + " collision events)"
                     : std::string("not dangerous")) +
        ", " + std::to_string(r.steps) + " steps";
    if (json) {
      PrintJson({{"command", "render"},
                 {"domain", domain},
                 {"method", ToString(eval::kMethodNames, m)},
                 {"seed", seed},
                 {"episode", episode},
                 {"frames", r.frames},
                 {"steps", r.steps},
                 {"success", r.success},
                 {"dangerous", r.dangerous},
                 {"collision_events", r.collision_events},
                 {"out", out.empty() ? nlohmann::json(nullptr) : nlohmann::json(out)},
                 {"frames_dir",
                  frames_dir.empty() ? nlohmann::json(nullptr) : nlohmann::json(frames_dir)}});
    } else {
      std::cout << r.frames << " frames of " << ToString(eval::kMethodNames, m) << " episode "
                << episode << " (seed " << seed << "): " << outcome << " -> "
                << (out.empty() ? frames_dir + "/" : out)
                << (!out.empty() && !frames_dir.empty() ? " and " + frames_dir + "/" : "") << "\n";
    }
  }
};

}  // namespace

void RegisterRenderCommand(CLI::App& app, const Config& config) {
  static RenderCommand render;
  render.config = &config;
  render.Register(app);
}

}  // namespace secure::cli
