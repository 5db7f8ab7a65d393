scene other1, database db/base-other1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 3 | 1649 | 69.0 % | 71.6 % | 71.9 % | 0.28 | 1649 | 66.2 % | 71.2 % | 71.9 % |
| view0.png view2.png | 3 | 865 | 69.2 % | 72.8 % | 74.8 % | 0.25 | 865 | 65.7 % | 71.6 % | 72.4 % |
| view0.png view3.png | 2 | 901 | 48.6 % | 51.1 % | 51.2 % | 1.27 | 901 | 45.9 % | 50.5 % | 51.2 % |
| view0.png view4.png | 3 | 869 | 44.3 % | 45.9 % | 46.3 % | 10.37 | 869 | 42.1 % | 45.7 % | 46.3 % |
| view1.png view2.png | 3 | 1319 | 75.4 % | 77.5 % | 77.9 % | 0.21 | 1319 | 72.5 % | 77.0 % | 77.7 % |
| view1.png view3.png | 3 | 963 | 56.9 % | 59.7 % | 61.1 % | 0.49 | 963 | 54.2 % | 58.8 % | 59.1 % |
| view1.png view4.png | 3 | 935 | 53.7 % | 55.7 % | 57.3 % | 0.60 | 935 | 50.5 % | 55.0 % | 55.6 % |
| view2.png view3.png | 3 | 1091 | 64.0 % | 68.7 % | 70.3 % | 0.29 | 1091 | 61.3 % | 65.6 % | 66.4 % |
| view2.png view4.png | 2 | 1034 | 64.7 % | 68.0 % | 68.3 % | 0.28 | 1034 | 62.7 % | 67.7 % | 68.3 % |
| view3.png view4.png | 3 | 1524 | 57.7 % | 62.3 % | 66.1 % | 0.49 | 1524 | 53.6 % | 58.5 % | 59.6 % |
| all pairs |  | 11150 | 61.4 % | 64.5 % | 65.7 % | 0.37 | 11150 | 58.5 % | 63.2 % | 63.9 % |
