% SLICOT's N4SID (IB01AD/IB01BD/IB01CD) through GNU Octave's control package, timed inside
% Octave: n4sid(iddata(y, u, ts), 3, 's', 20) -- order 3, 20 block rows, default Cholesky
% algorithm on the correlation matrix, D estimated.
%
% Usage: octave --no-gui --quiet --eval "octave_n4sid('LOG.csv', 'OUT.json', REPEATS)"
% Writes {"seconds": best of REPEATS, "a", "b", "c", "d", "ts", "control_version"} as JSON.
function octave_n4sid (log, out, repeats)
  if nargin < 3
    repeats = 5;
  end
  pkg load control;
  data = dlmread (log, ',', 1, 0);
  t = data(:, 1); u = data(:, 2); y = data(:, 3);
  ts = (t(end) - t(1)) / (numel (t) - 1);
  dat = iddata (y, u, ts);
  best = Inf;
  for k = 1:repeats
    t0 = tic ();
    sys = n4sid (dat, 3, 's', 20);
    best = min (best, toc (t0));
  end
  [a, b, c, d] = ssdata (sys);
  info = pkg ('list', 'control');
  res = struct ('seconds', best, 'a', a, 'b', b, 'c', c, 'd', d, 'ts', ts, ...
                'control_version', info{1}.version, 'octave_version', version ());
  fid = fopen (out, 'w');
  fputs (fid, jsonencode (res));
  fclose (fid);
  fprintf (stderr, 'octave: SLICOT n4sid %.4f s\n', best);
end
