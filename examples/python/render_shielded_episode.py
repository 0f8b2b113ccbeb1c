# One shielded episode of the Panda arm pushing a block, rendered with the overlay `secure render`
# draws (step, h(s), the shield's status, interventions, a plot of h) into an MP4 video
# (PYTHONPATH=build/python python3 this [OUT.mp4]; needs ffmpeg). The barrier and the policy are
# trained here on the domain's quick data set, in about a minute on one core: small, so expect a
# shield that intervenes often. With a run directory's models use Barrier.load / Policy.load.
import sys

import numpy as np

import secure

out = sys.argv[1] if len(sys.argv) > 1 else "panda_shielded.mp4"
data = secure.generate_data("panda-push", seed=0, profile="quick")
barrier, _ = secure.train_barrier(data["safe"], data["near_dangerous"], data["features"],
                                  hidden=[64, 64], max_epochs=40, seed=0)
policy, _ = secure.train_bc(data["demonstrations"], epochs=30, seed=0)

env = secure.make_env("panda-push", render_mode="rgb_array", render_size=(480, 360))
low, high = env.action_space.low, env.action_space.high  # the actuator box the shield keeps to
shield = secure.Shield(barrier, env.dynamics, seed=0, action_low=low, action_high=high)
overlay = secure.Overlay(title="BC + shield", max_steps=env.max_steps)

obs, _ = env.reset(seed=3)
interventions = outside = 0
with secure.VideoWriter(out, 480, 360, fps=20) as video:
    frame = env.render()
    assert frame is not None
    video.write(overlay.draw(frame, step=0, h=float(barrier.h(obs))))
    for t in range(1, env.max_steps + 1):
        decision = shield.decide(obs, policy.mean(obs), policy.sigma)
        assert np.all(decision.action >= low) and np.all(decision.action <= high)
        interventions += decision.intervened
        obs, reward, terminated, truncated, info = env.step(decision.action)
        frame = env.render()
        assert frame is not None
        video.write(overlay.draw(frame, step=t, h=float(barrier.h(obs)),
                                 status=decision.status, intervened=decision.intervened,
                                 collided=info["collided"], reached_goal=info["reached_goal"]))
        if terminated or truncated:
            break
print(f"{video.frames} frames -> {out}: goal={info['reached_goal']} "
      f"toppled={info['collided']} steps={t} interventions={interventions}")
