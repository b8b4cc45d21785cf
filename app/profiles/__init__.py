"""A run's indicator profiles as the API answers them: checked queries, the answer of a query
(read, aggregate, decimate, encode), its encoding and ETag, answers computed once per process,
and the streamed CSV/Parquet exports.

- :mod:`~app.profiles.query`: a profile query checked against the run's stored results;
- :mod:`~app.profiles.answer`: the rows of a query and their encoded answer;
- :mod:`~app.profiles.encoding`: JSON in rows or columns, ETag, gzip, request headers;
- :mod:`~app.profiles.cache`: answers computed once per process and kept in memory;
- :mod:`~app.profiles.export`: the pages of an export and the CSV and Parquet streams;
- :mod:`~app.profiles.impacts`: the track impacts of a run (profile rows grouped into impacts).
"""
