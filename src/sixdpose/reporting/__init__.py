"""Reporting, the layer above every stage: the experiment loop over several methods (:mod:`.compare`), the
paper's tables, figures and macros rebuilt from result artifacts (:mod:`.report`), the README's generated
blocks (:mod:`.readme`) and the paper's own published figures (:mod:`.paper`). Nothing below this layer
imports it."""
