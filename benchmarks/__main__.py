"""``python -m benchmarks``: every benchmark command, one line each."""

from __future__ import annotations

COMMANDS: dict[str, str] = {
    "table2": "the main job: the paper's Table II, our runs beside the paper's, its claims checked",
    "sampled": "agents over seeded episodes with sampled object motion: does epsilon bound the harm?",
    "stress": "every MPC over a seeded family of random scenes: collisions, fallbacks, step times",
    "heldout": "the RMPC and the SMPC in two-object crossings they were not tuned on",
    "timing": "the MPCs' solve time per step, fallbacks and real-time margin in the paper's loop",
    "env_speed": "one RiskCrossing-v0 step beside Gymnasium's CartPole-v1 and Pendulum-v1",
    "vector_speed": "the batched RiskCrossing-v0's throughput beside Gymnasium's envs",
    "exact_accuracy": "the exact risk against adaptive quadrature on random beliefs up to 1:1000",
    "highway_intersection": "our agents drive highway-env's intersection against its IDM",
    "prediction": "how well the paper's and the lane predictor predict the intersection's traffic",
    "highway_frontier": "the intersection's frontier: goal rate against collision rate, the IDM beside",
    "highway_frontier_runs": "the frontier of runs already made on the same episodes, in one figure",
    "highway_gate": "the junction gate's verdicts against what going at once would have done",
    "highway_render": "pictures through highway-env's graphics: the paper's episode, an intersection",
    "train_ppo": "train the PPO baseline (stable-baselines3) with a risk cost",
    "ppo_study": "short PPO runs behind the reward weights and the prediction features",
    "rollout": "one episode of one agent: smallest distance, largest risk, goal, collision",
}
"""Each command (``python -m benchmarks.NAME``), the main job first, with what it does."""


def main() -> str:
    width = max(map(len, COMMANDS))
    lines = ["The benchmark commands (python -m benchmarks.NAME --help: options, examples):"]
    lines += [f"  {name:<{width}}  {text}" for name, text in COMMANDS.items()]
    lines.append("Agents are named alike in all: rmpc[:RISK], smpc[:RISK][:SEVERITY:TOLERANCE][:budget=B],")
    lines.append("ppo:VARIANT, idm; lists are comma-separated (see benchmarks/agent_names.py).")
    text = "\n".join(lines)
    print(text)
    return text


if __name__ == "__main__":
    main()
