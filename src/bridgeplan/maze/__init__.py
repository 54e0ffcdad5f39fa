"""Maze2D: layouts (``layouts``), the batched simulator (``sim``), evaluation tasks (``tasks``), the
shortest-path expert (``expert``), Diffuser's tracking controller (``controllers``), batched
rollouts (``rollout``) and the normalized score (``reference``)."""
