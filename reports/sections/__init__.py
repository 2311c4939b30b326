"""The report's sections, one module each: each builds its tables and figures from the stored
tables and runs (:mod:`reports.data`) and returns :class:`reports.sections.base.Section`\\ s; the
order of the sections is :data:`reports.build.SECTIONS`."""
