"""Evaluation: prediction files and the operating threshold (``predict``), the official
View-of-Delft protocol (``metrics``), the grounding metrics of answer sets (``grounding``), the
baselines that read the prompt without the scene (``baselines``), the paper's tables
(``report``), RESULTS.md tables (``results_table``) and the class-prompt study
(``class_prompts``, ``class_prompt_counts``)."""
