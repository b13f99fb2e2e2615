"""What every algorithm (PPO, SAC, POCA, and BC / GAIL beside them) shares and none owns: the
networks and their parts, the action distributions, acting, the numpy views of the networks,
Adam, the trajectory the rollout hands a trainer, reward providers, schedules and GAE."""
